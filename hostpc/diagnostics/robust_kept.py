"""The chi-square of a robust-loss fit over the samples its loss keeps.

A robust loss (``--loss huber|cauchy``) down-weights a sample whose residual is far beyond
the rest, so its fitted values are those of the other samples; judging such a fit by the
chi2 of every sample would refuse it for the very measurements its loss set aside. The
samples left out of the test are the ones diagnose names as outliers (``outliers.
find_outliers``: the Bonferroni-corrected, scale-free leave-one-out test of each sample and
of each pose of several samples, at the adequacy level ``ADEQUACY_P_MIN``, refitted with
the same loss after each); a covariance wrong by a constant factor therefore leaves out
nothing, and at most ``MAX_OUTLIER_FRACTION`` of the samples is ever left out. The chi2 is
that of the fit's own values (the ones pushed) over the other samples, with m degrees of
freedom fewer per sample left out. A linear-loss fit is judged on every sample, as before.
`hostpc fit --effects auto` scores every model's held-out error without the samples this
rule leaves out on the default model (``model_choice``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import cast

import numpy as np

from hostpc.diagnostics.adequacy import ADEQUACY_P_MIN
from hostpc.diagnostics.outliers import find_outliers
from hostpc.diagnostics.sample_names import name_samples
from hostpc.fitting import FitResult, solve
from hostpc.fitting.solver import Loss
from hostpc.json_object import JsonObject


@dataclass(frozen=True)
class KeptSamples:
    """What a robust-loss fit is judged on. loss: the fit's loss; left_out: the samples set
    aside (dataset indices, ascending); max_weight: the largest robust weight among them
    (1 = a sample at the loss's scale counted in full); chi2, dof: over the other samples,
    at the fit's values; n_kept: how many samples that is; left_out_text: the samples set
    aside as the text names them (grouped by pose where a whole pose is out)."""

    loss: str
    left_out: tuple[int, ...]
    max_weight: float
    chi2: float
    dof: int
    n_kept: int
    left_out_text: str = ""

    @property
    def chi2_dof(self) -> float:
        return self.chi2 / self.dof if self.dof > 0 else math.nan

    def sentence(self) -> str:
        """'chi2/dof 0.91 over the 117 samples the cauchy loss keeps; #33, #34, #35
        down-weighted below 0.005'."""
        named = self.left_out_text or ", ".join(f"#{i}" for i in self.left_out)
        return (f"chi2/dof {self.chi2_dof:.3g} over the {self.n_kept} samples the {self.loss} "
                f"loss keeps; {named} down-weighted below {weight_bound(self.max_weight):g} "
                "(outliers by the leave-one-out test, left out of the chi-square test)")

    def to_json(self) -> JsonObject:
        """The "kept_samples" entry of `hostpc fit --json`'s model_adequacy."""
        return {"loss": self.loss, "left_out": list(self.left_out),
                "max_weight": self.max_weight, "chi2": self.chi2, "dof": self.dof,
                "chi2_dof": self.chi2_dof, "n_kept": self.n_kept}


def weight_bound(weight: float) -> float:
    """A round number just above ``weight`` (two significant digits, rounded up)."""
    if not weight > 0:
        return 0.0
    step = 10.0 ** (math.floor(math.log10(weight)) - 1)
    return math.ceil(weight / step * (1 - 1e-12)) * step


def kept_samples(result: FitResult, alpha: float = ADEQUACY_P_MIN) -> KeptSamples | None:
    """The samples a robust-loss fit keeps and its chi2 over them (module docstring); None
    for a linear loss, a fit that did not converge or has no degrees of freedom, or when no
    sample is an outlier (the fit is then judged on every sample)."""
    if result.loss == "linear" or not result.converged or result.dof <= 0:
        return None
    loss = cast(Loss, result.loss)

    def refit(fit: FitResult, keep: np.ndarray) -> FitResult:
        return solve(fit.problem.subset(keep), x0=fit.x, loss=loss, cv_folds=0)

    outliers, _ = find_outliers(result, alpha, refit)
    if not outliers:
        return None
    left_out = tuple(sorted(o.sample for o in outliers))
    n_samples, m = result.residuals_whitened.shape
    kept = np.ones(n_samples, dtype=bool)
    kept[list(left_out)] = False
    dof = result.dof - m * len(left_out)
    if dof <= 0:
        return None
    chi2 = float(np.sum(result.residuals_whitened[kept] ** 2))
    return KeptSamples(loss=loss, left_out=left_out,
                       max_weight=float(np.max(np.asarray(result.weights)[list(left_out)])),
                       chi2=chi2, dof=dof, n_kept=int(kept.sum()),
                       left_out_text=name_samples(left_out, result.problem.dataset.samples))
