"""Load, validate, convert and save ``zerocal-dataset/1`` files.

The contract is ``shared/spec/dataset-format.md``; the user documentation is
``docs/dataset-format.md``. Loading converts the file's units to SI (m, rad, s) and checks
everything a fit relies on; a file that breaks the contract raises
``hostpc.errors.DatasetError`` with one line naming the file, the field and the sample
index, e.g. ``data.json: samples[3].cov: not positive definite``. Saving writes SI units,
with floats written so that they read back exactly.

Split by concept: ``reading`` (parse + validate -> ``Dataset``; the samples in
``reading_samples``), ``writing`` (``Dataset`` -> document, atomic save) and ``units`` (file
units -> SI). This module is the stable import point for all of them.
"""

from hostpc.dataset.reading import PathLike, dataset_from_dict, load_dataset
from hostpc.dataset.writing import dataset_to_dict, save_dataset

__all__ = ["PathLike", "dataset_from_dict", "dataset_to_dict", "load_dataset", "save_dataset"]
