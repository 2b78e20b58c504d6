"""Fitting: Levenberg-Marquardt on whitened residuals, identifiability, FitResult."""

from hostpc.fit.fitting import fit, fold_indices, solve
from hostpc.fit.identifiability import Identifiability, NullDirection, analyse
from hostpc.fit.result import FitResult, ParameterEstimate

__all__ = ["fit", "solve", "fold_indices", "FitResult", "ParameterEstimate", "NullDirection",
           "Identifiability", "analyse"]
