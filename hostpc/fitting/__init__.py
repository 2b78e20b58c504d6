"""Fitting: Levenberg-Marquardt on whitened residuals, identifiability, FitResult."""

from hostpc.fitting.fitting import fit, fold_indices, solve
from hostpc.fitting.identifiability import Identifiability, NullDirection, analyse
from hostpc.fitting.result import FitResult, ParameterEstimate

__all__ = ["fit", "solve", "fold_indices", "FitResult", "ParameterEstimate", "NullDirection",
           "Identifiability", "analyse"]
