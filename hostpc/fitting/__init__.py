"""Fitting: Levenberg-Marquardt on whitened residuals, identifiability, FitResult."""

from hostpc.fitting.fitting import fit, solve
from hostpc.fitting.folds import fold_indices, pose_groups
from hostpc.fitting.identifiability import Identifiability, NullDirection, analyse
from hostpc.fitting.result import FitResult, ParameterEstimate

__all__ = ["fit", "solve", "fold_indices", "pose_groups", "FitResult", "ParameterEstimate",
           "NullDirection", "Identifiability", "analyse"]
