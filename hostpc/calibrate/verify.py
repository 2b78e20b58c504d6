"""Verification: fresh poses measured after the push, tested against the stated noise.

The verification poses are planned at the start with the fit poses but are none of them.
They are measured after the push (with the new offsets in the controller) and predicted
twice with the fitted frames and effects:

- after: the model with the pushed corrections now inside the controller's angles
  (joint offset parameters `x_q - d`, d = the pushed corrections);
- before: the old model, i.e. the controller's previous offsets and no zero correction
  (joint offset parameters `-d`). With nothing pushed (`--no-push`, a refused push),
  d = 0: after = the full fitted model; the verdict is then a check of the model on fresh
  poses, not of any offsets.

The verdict is a chi-square test with a stated false-FAIL rate `alpha` (default 1 %):

    r = measured - predicted_after                      (K samples x m, stacked: n = K m)
    S = F^2 C + J Sigma_x J^T                           (n, n)
    T = r^T S^-1 r  ~  chi-square(n)  if the calibration is right

C: the stated measurement covariances (block diagonal, from the dataset; F = the
`--verify-factor`, default 1: the stated noise as it is); J: (n, P) the prediction's
Jacobian at the fitted parameters, Sigma_x: (P, P) the fit's parameter covariance (in the
stated-noise scale, zero where a parameter is held fixed): the prediction is uncertain too,
and that uncertainty is common to every verification pose. FAIL if the p-value
`P(chi-square(n) >= T) < alpha`, or if a station tolerance is set (`--verify-tolerance`) and
the RMS after exceeds it. A correct calibration fails with probability alpha (less if the
stated covariances are conservative, as the `--pixel-floor` inflation makes them);
docs/calibrate.md says how many verification poses detect a given model error.

Residual RMS and max are over samples of the norm of the raw residual
`measured - predicted` (m): the same metric as the fit's `rms` (`FitResult.rms`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from hostpc.dataset import Dataset
from hostpc.diagnostics.distributions import chi2_sf
from hostpc.fitting import FitResult
from hostpc.json_object import JsonObject
from hostpc.model.joint_offsets import PushTable
from hostpc.model.measurements.predict import predict
from hostpc.model.problem import build_problem

DEFAULT_VERIFY_ALPHA = 0.01
"""The verification's false-FAIL rate: a correct calibration FAILs this often at most."""
DEFAULT_VERIFY_FACTOR = 1.0
"""Measurement noise of the test = this x the stated noise (1: as stated)."""


def noise_rms(dataset: Dataset) -> float:
    """The STATED noise: sqrt(mean trace(cov)) of a dataset's measurement covariances (m)."""
    cov = dataset.samples.cov
    sigma = dataset.samples.sigma
    if cov is None and sigma is not None and sigma.shape[0]:  # sphere_probe: 1-D distances
        return float(np.sqrt(np.mean(sigma**2)))
    if cov is None or cov.shape[0] == 0:
        return float("nan")
    return float(np.sqrt(np.mean(np.trace(cov, axis1=1, axis2=2))))


def measured_noise_rms(result: FitResult) -> float:
    """The noise the fit measured (m): its per-sample raw residual-norm RMS corrected for
    the fitted parameters, `rms * sqrt(n_rows / dof)` (n_rows: scalar residuals, dof:
    n_rows - free parameters). NaN without degrees of freedom."""
    n_rows = int(np.size(result.residuals_whitened))
    if result.dof < 1 or n_rows < 1:
        return float("nan")
    return float(result.rms * np.sqrt(n_rows / result.dof))


@dataclass(frozen=True)
class VerifyResult:
    """The verification of a run (module doc).

    rms/max before and after (m); statistic: the chi-square T, dof: its degrees of freedom
    (scalar residuals), p_value: P(chi2(dof) >= T); alpha: the false-FAIL rate; tolerance:
    the station's RMS tolerance (m) or None; passed: p_value >= alpha and (no tolerance or
    rms_after <= tolerance); n_planned poses / n_measured samples; pushed: False if nothing
    was pushed (a model check); stated_noise_rms (m): sqrt(mean trace(cov)) of the
    verification samples; factor: the noise factor F of the test."""

    n_planned: int
    n_measured: int
    rms_before: float
    max_before: float
    rms_after: float
    max_after: float
    statistic: float
    dof: int
    p_value: float
    alpha: float
    tolerance: float | None
    passed: bool
    stated_noise_rms: float = float("nan")
    factor: float = DEFAULT_VERIFY_FACTOR
    pushed: bool = True

    @property
    def verdict(self) -> str:
        return "PASS" if self.passed else "FAIL"

    @property
    def reason(self) -> str:
        """Why it failed ("" for a pass)."""
        reasons = []
        if not self.p_value >= self.alpha:
            reasons.append(f"p = {self.p_value:.3g} < alpha = {self.alpha:g}")
        if self.tolerance is not None and not self.rms_after <= self.tolerance:
            reasons.append(f"RMS {self.rms_after * 1e3:.4f} mm > tolerance "
                           f"{self.tolerance * 1e3:g} mm")
        return "; ".join(reasons)

    def to_dict(self) -> JsonObject:
        """JSON form in millimetres (result.json's `verify`, verify.json)."""
        return {
            "verdict": self.verdict,
            "statistic": _finite(self.statistic),
            "dof": self.dof,
            "p_value": _finite(self.p_value),
            "alpha": self.alpha,
            "rms_mm": _finite(self.rms_after * 1e3),
            "tolerance_mm": None if self.tolerance is None else self.tolerance * 1e3,
            "n_poses": self.n_planned,
            "n_planned": self.n_planned,
            "n_measured": self.n_measured,
            "rms_before_mm": _finite(self.rms_before * 1e3),
            "max_before_mm": _finite(self.max_before * 1e3),
            "rms_after_mm": _finite(self.rms_after * 1e3),
            "max_after_mm": _finite(self.max_after * 1e3),
            "stated_noise_rms_mm": _finite(self.stated_noise_rms * 1e3),
            "factor": self.factor,
            "reason": self.reason,
            "passed": self.passed,
            "pushed": self.pushed,
            "kind": "offsets" if self.pushed else "model_check",
        }


def _finite(value: float) -> float | None:
    return value if np.isfinite(value) else None


def chi_square_statistic(residual: np.ndarray, sqrt_information: np.ndarray,
                         jacobian: np.ndarray, covariance_x: np.ndarray,
                         factor: float = DEFAULT_VERIFY_FACTOR) -> tuple[float, int]:
    """T = r^T S^-1 r with S = F^2 C + J Sigma_x J^T, and its dof (module doc).

    residual: (K, m) measured - predicted; sqrt_information: (K, m, m) W with
    W^T W = C^-1 per sample; jacobian: (K, m, P) d predicted / d x; covariance_x: (P, P)
    the fitted parameters' covariance (NaN entries count as zero). Computed in whitened
    coordinates: S_w = F^2 I + (W J) Sigma_x (W J)^T."""
    K, m = residual.shape
    n = K * m
    if n == 0:
        return math.nan, 0
    r_w = np.einsum("kij,kj->ki", sqrt_information, residual).reshape(n)
    J_w = np.einsum("kij,kjp->kip", sqrt_information, jacobian).reshape(n, -1)
    sigma_x = np.nan_to_num(np.asarray(covariance_x, float), nan=0.0)
    S = factor**2 * np.eye(n) + J_w @ sigma_x @ J_w.T
    return float(r_w @ np.linalg.solve(S, r_w)), n


def evaluate_verify(result: FitResult, dataset: Dataset, pushed_delta: np.ndarray,
                    n_planned: int, alpha: float = DEFAULT_VERIFY_ALPHA,
                    tolerance: float | None = None,
                    factor: float = DEFAULT_VERIFY_FACTOR) -> VerifyResult:
    """Test the verification measurements against the new model (module doc).

    pushed_delta: (n,) rad written into the controller before these measurements (all
    zero: nothing pushed, a model check); tolerance: station RMS tolerance (m) or None."""
    fitted = result.problem
    problem = build_problem(dataset, list(fitted.effect_names), plugins=fitted.plugins,
                            effect_instances=[t.effect for t in fitted.terms])
    if problem.layout.names != fitted.layout.names:
        raise ValueError("verification model layout differs from the fit's")
    x_after = result.x.copy()
    x_before = result.x.copy()
    delta = np.asarray(pushed_delta, float)
    offset_names = PushTable.for_controller(delta.size, problem.context.joint_labels).names
    for name, d in zip(offset_names, delta, strict=True):
        if name in problem.layout.names:
            k = problem.layout.index(name)
            x_after[k] = result.x[k] - d
            x_before[k] = -d
    predicted_after, jacobian = predict(problem, x_after, jacobian=True)
    predicted_before, _ = predict(problem, x_before, jacobian=False)
    residual = problem.measured - predicted_after
    assert jacobian is not None
    statistic, dof = chi_square_statistic(residual, problem.sqrt_information, jacobian,
                                          result.covariance, factor)
    p_value = chi2_sf(statistic, dof) if dof > 0 else math.nan
    after = np.linalg.norm(residual, axis=1)
    before = np.linalg.norm(problem.measured - predicted_before, axis=1)

    def rms(v: np.ndarray) -> float:
        return float(np.sqrt(np.mean(v**2))) if v.size else float("nan")

    def peak(v: np.ndarray) -> float:
        return float(np.max(v)) if v.size else float("nan")

    rms_after = rms(after)
    passed = bool(np.isfinite(p_value) and p_value >= alpha
                  and (tolerance is None or rms_after <= tolerance))
    return VerifyResult(
        n_planned=n_planned, n_measured=dataset.n_samples,
        rms_before=rms(before), max_before=peak(before),
        rms_after=rms_after, max_after=peak(after),
        statistic=statistic, dof=dof, p_value=p_value, alpha=alpha, tolerance=tolerance,
        passed=passed, stated_noise_rms=noise_rms(dataset), factor=factor,
        pushed=bool(np.any(delta != 0.0)),
    )
