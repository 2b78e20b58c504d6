"""Verification: fresh poses measured after the push, compared before vs after.

The verification poses are planned at the start with the fit poses but are none of them.
They are measured after the push (with the new offsets in the controller), then predicted
twice with the fitted frames and effects:

- after: the model with the pushed corrections now inside the controller's angles
  (joint offset parameters `x_q - d`, d = the pushed corrections);
- before: the old model, i.e. the controller's previous offsets and no zero correction
  (joint offset parameters `-d`: the old controller would report `q - d` at the same
  physical pose). With nothing pushed (`--no-push`, a refused push), d = 0: after = the
  full fitted model, before = the fitted frames without the joint offsets; the verdict is
  then a check of the model on fresh poses, not of any offsets.

Residual RMS and max are over samples of the norm of the raw residual
`measured - predicted` (m): the same metric as the fit's `rms` (`FitResult.rms`).

The noise level the verdict compares with is the one the fit MEASURED, not the one the
covariances state (they include the `--pixel-floor` inflation: chi2/dof about 0.44 in the
default simulated run, so the stated figure is about 1.5 times the real noise):

- `measured_noise_rms(fit)` = `fit_rms * sqrt(n_rows / dof)`: the fit's per-sample
  residual-norm RMS corrected for the parameters it fitted, the noise of the fit's own
  samples in that metric;
- the verification samples lie at other poses (a random choice, while the fit's poses are
  picked for information, which favours low-noise poses: in dual_loop the verification
  samples' stated noise is 1.5 times the fit samples'). So the reference of the verdict is
  that measured noise carried to the verification samples: their stated noise
  `sqrt(mean trace(cov))` times the scale the fit measured for the stated covariances,
  `sqrt(chi2/dof)`. For samples of one isotropic covariance it equals
  `measured_noise_rms`. The scale is capped at the upper edge of the fit's chi-square band
  (`push.chi2_dof_upper`): a larger chi2/dof is model error, not noise (and it refuses the
  push), so it must not loosen the verdict.

The stated figure is kept as secondary information. Verdict: pass if RMS after <= factor x
measured noise RMS (default 1.2).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from hostpc.dataset import Dataset
from hostpc.fitting import FitResult
from hostpc.methods.planning import joint_offset_names
from hostpc.methods.push import chi2_dof_upper
from hostpc.model.measurement import predict
from hostpc.model.problem import build_problem

DEFAULT_VERIFY_FACTOR = 1.2


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
    """Before/after residual RMS and max (m); noise_rms: the noise the fit measured,
    carried to the verification samples (m), the verdict's reference = stated_noise_rms
    (sqrt(mean trace(cov)) of the verification samples, m) x noise_scale (sqrt(chi2/dof)
    of the fit, capped at its band); threshold = factor x noise_rms (m) and the verdict;
    n_planned poses / n_measured samples; pushed: False if nothing was pushed (the verdict
    then checks the model on fresh poses, not offsets)."""

    n_planned: int
    n_measured: int
    rms_before: float
    max_before: float
    rms_after: float
    max_after: float
    noise_rms: float
    factor: float
    threshold: float
    passed: bool
    stated_noise_rms: float = float("nan")
    noise_scale: float = float("nan")
    pushed: bool = True

    def to_dict(self) -> dict[str, Any]:
        """JSON form in millimetres (a report value)."""
        return {
            "n_planned": self.n_planned,
            "n_measured": self.n_measured,
            "rms_before_mm": self.rms_before * 1e3,
            "max_before_mm": self.max_before * 1e3,
            "rms_after_mm": self.rms_after * 1e3,
            "max_after_mm": self.max_after * 1e3,
            "noise_rms_mm": _finite(self.noise_rms * 1e3),
            "stated_noise_rms_mm": _finite(self.stated_noise_rms * 1e3),
            "noise_scale": _finite(self.noise_scale),
            "factor": self.factor,
            "threshold_mm": _finite(self.threshold * 1e3),
            "passed": self.passed,
            "pushed": self.pushed,
            "kind": "offsets" if self.pushed else "model_check",
        }


def _finite(value: float) -> float | None:
    return value if np.isfinite(value) else None


def evaluate_verify(result: FitResult, dataset: Dataset, pushed_delta: np.ndarray,
                    n_planned: int, factor: float = DEFAULT_VERIFY_FACTOR) -> VerifyResult:
    """Compare the verification measurements with the old and the new model (module doc).

    pushed_delta: (n,) rad written into the controller before these measurements (all
    zero: nothing pushed, a model check)."""
    fitted = result.problem
    problem = build_problem(dataset, list(fitted.effect_names), plugins=fitted.plugins,
                            effect_instances=[t.effect for t in fitted.terms])
    if problem.layout.names != fitted.layout.names:
        raise ValueError("verification model layout differs from the fit's")
    x_after = result.x.copy()
    x_before = result.x.copy()
    delta = np.asarray(pushed_delta, float)
    offset_names = joint_offset_names(delta.size, problem.context.joint_labels)
    for name, d in zip(offset_names, delta, strict=True):
        if name in problem.layout.names:
            k = problem.layout.index(name)
            x_after[k] = result.x[k] - d
            x_before[k] = -d
    norms = {}
    for label, x in (("after", x_after), ("before", x_before)):
        predicted, _ = predict(problem, x, jacobian=False)
        norms[label] = np.linalg.norm(problem.measured - predicted, axis=1)
    stated = noise_rms(dataset)
    scale = math.sqrt(min(result.chi2_dof, chi2_dof_upper(result.dof)))
    noise = stated * scale

    def rms(v: np.ndarray) -> float:
        return float(np.sqrt(np.mean(v**2))) if v.size else float("nan")

    rms_after = rms(norms["after"])
    threshold = factor * noise
    return VerifyResult(
        n_planned=n_planned,
        n_measured=dataset.n_samples,
        rms_before=rms(norms["before"]),
        max_before=float(np.max(norms["before"])) if norms["before"].size else float("nan"),
        rms_after=rms_after,
        max_after=float(np.max(norms["after"])) if norms["after"].size else float("nan"),
        noise_rms=noise,
        factor=factor,
        threshold=threshold,
        passed=bool(np.isfinite(rms_after) and rms_after <= threshold),
        stated_noise_rms=stated,
        noise_scale=scale,
        pushed=bool(np.any(delta != 0.0)),
    )
