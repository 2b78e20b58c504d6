"""Calibration dataset files (``zerocal-dataset/1``) and their in-memory value.

``load_dataset``/``dataset_from_dict`` validate a file and convert it to SI units;
``save_dataset``/``dataset_to_dict`` write one back. Bad input raises
``hostpc.errors.DatasetError`` with a one-line message naming the file, the field and the
sample index. The format is documented in ``docs/dataset-format.md``.
"""

from hostpc.dataset.model import (
    Dataset,
    FramePose,
    RobotDescription,
    Samples,
    SphereFrame,
)
from hostpc.dataset.reading import dataset_from_dict, load_dataset
from hostpc.dataset.schema import FORMAT_TAG
from hostpc.dataset.writing import dataset_to_dict, save_dataset

__all__ = [
    "FORMAT_TAG",
    "Dataset",
    "FramePose",
    "RobotDescription",
    "Samples",
    "SphereFrame",
    "dataset_from_dict",
    "dataset_to_dict",
    "load_dataset",
    "save_dataset",
]
