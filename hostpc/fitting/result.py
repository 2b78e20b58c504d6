"""FitResult: the frozen value a fit returns, and its JSON form."""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property
from typing import Protocol

import numpy as np

from hostpc.dataset.writing import frames_to_json
from hostpc.fitting.identifiability import NullDirection
from hostpc.json_object import JsonObject
from hostpc.model.context import robot_identity
from hostpc.model.layout import Problem

CORRELATION_THRESHOLD = 0.9


class FitVerdict(Protocol):
    """What the push guard and the joint status read of a fit: a live `FitResult`, or a fit
    saved by `hostpc fit --json` and read back (`hostpc.calibrate.offline_push.SavedFit`).

    names: parameter names; x, std (NaN where fixed), fixed: (P,); joint_labels: the
    joints' names (q1..qn, or a kinematic tree's head.q1, ...); problem: the problem that
    produced the fit, None for a saved fit (it carries no priors, holds or dataset)."""

    @property
    def names(self) -> tuple[str, ...]: ...
    @property
    def joint_labels(self) -> tuple[str, ...]: ...
    @property
    def problem(self) -> Problem | None: ...
    @property
    def x(self) -> np.ndarray: ...
    @property
    def std(self) -> np.ndarray: ...
    @property
    def fixed(self) -> np.ndarray: ...
    @property
    def unidentifiable(self) -> tuple[NullDirection, ...]: ...
    @property
    def converged(self) -> bool: ...
    @property
    def message(self) -> str: ...
    @property
    def dof(self) -> int: ...
    @property
    def chi2_dof(self) -> float: ...
    @property
    def chi2_dof_with_calibration(self) -> float | None: ...


@dataclass(frozen=True)
class ParameterEstimate:
    """One parameter: value (SI delta from nominal), std (None if held fixed), unit."""

    name: str
    value: float
    std: float | None
    unit: str
    fixed: bool


@dataclass(frozen=True)
class FitResult:
    """Everything a fit found, and the problem that produced it.

    x: (P,) parameter vector; std: (P,) standard deviations (NaN where fixed);
    fixed: (P,) bool; covariance: (P, P) (zero rows/columns where fixed);
    residuals_raw: (N, m) measured - predicted (m); residuals_whitened: (N, m);
    rms / max: RMS and max over samples of the raw residual norm (m);
    chi2 = sum of squared whitened residuals; dof = N*m - free parameters;
    rank, singular_values (relative), condition_number: of the normalised Jacobian;
    unidentifiable: null directions held fixed; correlations: (a, b, rho) with |rho| > 0.9;
    cv_rms: k-fold cross-validated RMS (m) or None; weights: robust IRLS weights per sample.
    """

    problem: Problem
    x: np.ndarray
    std: np.ndarray
    fixed: np.ndarray
    covariance: np.ndarray
    residuals_raw: np.ndarray
    residuals_whitened: np.ndarray
    weights: np.ndarray
    rms: float
    max: float
    chi2: float
    dof: int
    rank: int
    singular_values: np.ndarray
    condition_number: float
    unidentifiable: tuple[NullDirection, ...]
    correlations: tuple[tuple[str, str, float], ...]
    converged: bool
    iterations: int
    message: str
    cv_rms: float | None
    cv_folds: int
    loss: str

    def __post_init__(self) -> None:
        for name in ("x", "std", "fixed", "covariance", "residuals_raw", "residuals_whitened",
                     "weights", "singular_values"):
            array = np.array(getattr(self, name), copy=True)
            array.setflags(write=False)
            object.__setattr__(self, name, array)

    @property
    def names(self) -> tuple[str, ...]:
        return self.problem.layout.names

    @property
    def joint_labels(self) -> tuple[str, ...]:
        return self.problem.context.joint_labels

    @property
    def chi2_dof(self) -> float:
        return self.chi2 / self.dof if self.dof > 0 else math.nan

    @property
    def parameters(self) -> dict[str, ParameterEstimate]:
        units = self.problem.layout.units
        return {
            name: ParameterEstimate(
                name=name,
                value=float(self.x[k]),
                std=None if self.fixed[k] else float(self.std[k]),
                unit=units[k],
                fixed=bool(self.fixed[k]),
            )
            for k, name in enumerate(self.names)
        }

    def value(self, name: str) -> float:
        return float(self.x[self.problem.layout.index(name)])

    def sigma(self, name: str) -> float:
        return float(self.std[self.problem.layout.index(name)])

    def effect_values(self, effect: str) -> np.ndarray:
        """The parameter values of one effect (in layout order)."""
        return self.x[self.problem.layout.effect_slices[effect]].copy()

    @property
    def residual_norms(self) -> np.ndarray:
        """(N,) norm of each sample's raw residual (m; its length components)."""
        return np.linalg.norm(self.residuals_raw[:, self.problem.length_columns], axis=1)

    def to_dict(self) -> JsonObject:
        """JSON document (SI units and radians) with the keys of the CLI's --json."""

        def finite(v: float | None) -> float | None:
            return None if v is None or not math.isfinite(v) else float(v)

        return {
            "method": self.problem.method,
            "robot": self.problem.dataset.robot.name,
            "robot_identity": robot_identity(self.problem.dataset),
            "effects": list(self.problem.effect_names),
            # the dataset's nominal frames (SI): with the frame parameters below they are the
            # fitted frames, absolute, that `hostpc predict` applies to another dataset
            "frames": frames_to_json(self.problem.dataset.frames),
            "parameters": {
                p.name: {"value": p.value, "std": finite(p.std), "unit": p.unit,
                         "fixed": p.fixed}
                for p in self.parameters.values()
            },
            "rms": self.rms,
            "max": self.max,
            "chi2": self.chi2,
            "dof": self.dof,
            "chi2_dof": finite(self.chi2_dof),
            "converged": self.converged,
            "iterations": self.iterations,
            "message": self.message,
            "rank": self.rank,
            "n_parameters": len(self.names),
            "n_samples": int(self.residuals_raw.shape[0]),
            "singular_values": [float(s) for s in self.singular_values],
            "condition_number": finite(self.condition_number),
            "unidentifiable": [d.to_dict() for d in self.unidentifiable],
            "correlations": [
                {"a": a, "b": b, "rho": rho} for a, b, rho in self.correlations
            ],
            "cv_rms": finite(self.cv_rms),
            "cv_folds": self.cv_folds,
            "loss": self.loss,
            **self._shared_chi2_entry(),
        }

    def _shared_chi2_entry(self) -> JsonObject:
        """{"chi2_dof_with_calibration": ...} when the fit has it (an offline `hostpc push`
        reads it from this document), else nothing."""
        full = self.chi2_dof_with_calibration
        return {} if full is None else {"chi2_dof_with_calibration": full}

    @cached_property
    def chi2_dof_with_calibration(self) -> float | None:
        """The chi2/dof with the dataset's rig / camera calibration covariance inside
        (`hostpc.fitting.shared_chi2`): the one chi2 the push guard, the runner's growing of
        a short plan and `hostpc diagnose` judge. None when the fit did not converge, its
        dataset carries no such covariance, or that chi2 is not finite or has another dof
        (then the plain chi2 is judged). Computed once per result."""
        from hostpc.fitting.shared_errors import result_shared_chi2

        if not self.converged:
            return None
        full = result_shared_chi2(self)
        if full is None or full.dof != self.dof or not math.isfinite(full.chi2_dof):
            return None
        return full.chi2_dof
