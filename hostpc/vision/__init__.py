"""Stereo vision: rig calibration, rectification, target detection, triangulation.

Pure numerics (numpy, OpenCV); no I/O except the rig file and image folders. The entry
points are `calibrate_rig` (S201), `save_rig` / `load_rig`, and `TargetMeasurer` (S202-S205).
See docs/vision.md.
"""

from hostpc.vision.measure import TargetMeasurer, TargetObservation, TargetRejected
from hostpc.vision.rig import StereoRig, load_rig, rig_from_dict, save_rig
from hostpc.vision.rig_calibration import (
    ChessboardSpec,
    RigCalibration,
    calibrate_rig,
    find_chessboard,
    load_image_pairs,
)

__all__ = [
    "ChessboardSpec",
    "RigCalibration",
    "StereoRig",
    "TargetMeasurer",
    "TargetObservation",
    "TargetRejected",
    "calibrate_rig",
    "find_chessboard",
    "load_image_pairs",
    "load_rig",
    "rig_from_dict",
    "save_rig",
]
