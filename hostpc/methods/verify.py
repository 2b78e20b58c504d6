"""Verification: fresh poses measured after the push, compared before vs after.

The verification poses are planned at the start with the fit poses but are none of them.
They are measured after the push (with the new offsets in the controller), then predicted
twice with the fitted frames and effects:

- after: the model with the pushed corrections now inside the controller's angles
  (joint offset parameters `x_q - d`, d = the pushed corrections);
- before: the old model, i.e. the controller's previous offsets and no zero correction
  (joint offset parameters `-d`: the old controller would report `q - d` at the same
  physical pose). With nothing pushed (`--no-push`), d = 0: after = the full fitted model,
  before = the fitted frames without the joint offsets.

Residual RMS and max are over poses of the norm of `measured - predicted` (m). The expected
noise RMS is `sqrt(mean trace(cov))` over the verification samples: the RMS residual norm a
perfect model would leave. Verdict: pass if RMS after <= factor x noise RMS (default 1.5).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from hostpc.dataset import Dataset
from hostpc.fitting import FitResult
from hostpc.methods.planning import joint_offset_names
from hostpc.model.measurement import predict
from hostpc.model.problem import build_problem

DEFAULT_VERIFY_FACTOR = 1.5


def noise_rms(dataset: Dataset) -> float:
    """sqrt(mean trace(cov)) of a dataset's measurement covariances (m)."""
    cov = dataset.samples.cov
    sigma = dataset.samples.sigma
    if cov is None and sigma is not None and sigma.shape[0]:  # sphere_probe: 1-D distances
        return float(np.sqrt(np.mean(sigma**2)))
    if cov is None or cov.shape[0] == 0:
        return float("nan")
    return float(np.sqrt(np.mean(np.trace(cov, axis1=1, axis2=2))))


@dataclass(frozen=True)
class VerifyResult:
    """Before/after residual RMS and max (m), expected noise RMS (m), threshold (m) and
    the verdict; n_planned / n_measured poses."""

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

    def to_dict(self) -> dict[str, Any]:
        """JSON form in millimetres (a report value)."""
        return {
            "n_planned": self.n_planned,
            "n_measured": self.n_measured,
            "rms_before_mm": self.rms_before * 1e3,
            "max_before_mm": self.max_before * 1e3,
            "rms_after_mm": self.rms_after * 1e3,
            "max_after_mm": self.max_after * 1e3,
            "noise_rms_mm": self.noise_rms * 1e3,
            "factor": self.factor,
            "threshold_mm": self.threshold * 1e3,
            "passed": self.passed,
        }


def evaluate_verify(result: FitResult, dataset: Dataset, pushed_delta: np.ndarray,
                    n_planned: int, factor: float = DEFAULT_VERIFY_FACTOR) -> VerifyResult:
    """Compare the verification measurements with the old and the new model (module doc).

    pushed_delta: (n,) rad written into the controller before these measurements."""
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
    noise = noise_rms(dataset)

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
    )
