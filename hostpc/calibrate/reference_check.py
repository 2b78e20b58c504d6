"""Is the cell reference still true? Each referenced frame tested against this run's data.

After the fit with every reference prior, each referenced frame in turn is freed (its prior
dropped) and the data refitted. The freed estimate x_F is compared with the reference
r_F by the Mahalanobis distance with the combined covariance C = C_ref (with the mount
floor) + C_fit (the freed fit's covariance of the frame, the rig's shared error inside):

    D^2 = min_a (d + N a)^T C^-1 (d + N a),   d = x_F - r_F

where N holds the frame's part of every direction the data cannot see once the frame is
freed (the joint its prior made identifiable: the target's rotation about base z with
joint 1, the camera's about the flange axis with joint 6). A move along N is a joint error
by another name: no data can tell them apart, so it is projected out (the frame "moved at
least" d + N a), and the test has dof = K - rank(N). Under "nothing moved" D^2 follows a
chi-square with dof degrees of freedom; a frame is flagged MOVED when D^2 exceeds its upper
alpha / n_frames quantile (Bonferroni over the frames: the whole check's false-alarm rate
is at most alpha, default 0.01). Of the flagged frames the likely cause is the one with the
smallest p-value (freeing the frame that really moved explains the data; freeing another
only partly).

Pure numerics (it fits; no I/O): the runner and bench/bench_reference.py call it.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from hostpc.calibrate.reference import FramePrior
from hostpc.diagnostics.adequacy import chi2_dof_upper, chi2_p_value
from hostpc.fitting import FitResult, fit
from hostpc.json_object import JsonObject

DEFAULT_ALPHA = 0.01
"""False-alarm rate of the whole reference check (all frames together)."""
LEVER_ARM_M = 0.1
"""How a move's size is reported when part of it is unseen: the representative nearest to
no move, an angle counting as the displacement it makes 0.1 m away (the test itself uses
the covariance metric)."""


@dataclass(frozen=True)
class FrameCheck:
    """One referenced frame against this run's data.

    distance2: D^2; dof: checkable directions (0: the data cannot check this frame);
    threshold: D^2 above which it is flagged; p_value; moved; translation_mm /
    rotation_deg: size of the smallest move that explains the data (None where the frame
    has no such part); confounded: joints a move along the unseen directions would be."""

    frame: str
    distance2: float
    dof: int
    threshold: float
    p_value: float
    moved: bool
    translation_mm: float | None
    rotation_deg: float | None
    confounded: tuple[str, ...] = ()

    def size_text(self) -> str:
        parts = []
        if self.translation_mm is not None:
            parts.append(f"{self.translation_mm:.2f} mm")
        if self.rotation_deg is not None:
            parts.append(f"{self.rotation_deg:.3f} deg")
        return " and ".join(parts) or "an unknown amount"

    def to_dict(self) -> JsonObject:
        return {"frame": self.frame, "distance2": _finite(self.distance2), "dof": self.dof,
                "threshold": _finite(self.threshold), "p_value": _finite(self.p_value),
                "moved": self.moved, "translation_mm": self.translation_mm,
                "rotation_deg": self.rotation_deg, "confounded": list(self.confounded)}


@dataclass(frozen=True)
class ReferenceCheck:
    """Every referenced frame's check. likely_cause: the frame named as moved, or None."""

    alpha: float
    frames: tuple[FrameCheck, ...]
    likely_cause: str | None

    @property
    def moved(self) -> bool:
        return self.likely_cause is not None

    def cause(self) -> FrameCheck | None:
        return next((f for f in self.frames if f.frame == self.likely_cause), None)

    def to_dict(self) -> JsonObject:
        return {"alpha": self.alpha, "moved": self.moved, "likely_cause": self.likely_cause,
                "frames": [f.to_dict() for f in self.frames]}


def _finite(value: float) -> float | None:
    return float(value) if math.isfinite(value) else None


def _without_block(dataset: Any, frame: str) -> Any:
    blocks = [b for b in dataset.extra_fields.get("prior_blocks") or []
              if b.get("reference_frame") != frame]
    return dataclasses.replace(dataset, extra_fields={**dataset.extra_fields,
                                                      "prior_blocks": blocks})


def _unseen_directions(freed: FitResult, full: FitResult, names: Sequence[str]
                       ) -> tuple[np.ndarray, tuple[str, ...]]:
    """(K, M) the frame's part of each direction the freed fit cannot see that the full
    fit could, and the joints (or other parameters) held for them."""
    before = {d.fixed for d in full.unidentifiable}
    columns, held = [], []
    for direction in freed.unidentifiable:
        if direction.fixed in before:
            continue
        coefficients = dict(zip(direction.parameters, direction.coefficients, strict=True))
        column = np.array([coefficients.get(n, 0.0) for n in names])
        if np.any(column != 0.0):
            columns.append(column)
            held.append(direction.fixed)
    if not columns:
        return np.zeros((len(names), 0)), ()
    return np.stack(columns, axis=1), tuple(held)


def check_frame(full: FitResult, prior: FramePrior, n_frames: int, alpha: float,
                effects: Any = None, plugins: Sequence[str] = (), loss: str = "linear"
                ) -> FrameCheck:
    """Free `prior`'s frame, refit from the full fit's solution, and test (module
    docstring)."""
    dataset = _without_block(full.problem.dataset, prior.frame)
    freed = fit(dataset, effects, plugins=plugins, loss=loss, cv_folds=0, x0=full.x)
    index = [freed.names.index(n) for n in prior.names]
    free = ~np.asarray(freed.fixed, bool)[index]
    d = (np.asarray(freed.x, float)[index] - prior.value)[free]
    C = (prior.covariance[np.ix_(free, free)]
         + np.asarray(freed.covariance, float)[np.ix_(index, index)][np.ix_(free, free)])
    names = [n for n, f in zip(prior.names, free, strict=True) if f]
    N, confounded = _unseen_directions(freed, full, names)
    C_inv = np.linalg.pinv(C)
    angles = [k for k, n in enumerate(names) if n.rsplit(".", 1)[-1] in ("rx", "ry", "rz")]
    lengths = [k for k in range(len(names)) if k not in angles]
    size = d.copy()  # the move's size: the nearest representative, angles x LEVER_ARM_M
    if N.shape[1]:
        a = -np.linalg.lstsq(N.T @ C_inv @ N, N.T @ C_inv @ d, rcond=None)[0]
        scale = np.where(np.isin(np.arange(len(names)), angles), LEVER_ARM_M, 1.0)
        b = -np.linalg.lstsq(scale[:, None] * N, scale * d, rcond=None)[0]
        size = d + N @ b
        d = d + N @ a
        rank = int(np.linalg.matrix_rank(N))
    else:
        rank = 0
    distance2 = float(d @ C_inv @ d)
    dof = len(names) - rank
    per_frame = alpha / max(n_frames, 1)
    threshold = chi2_dof_upper(dof, per_frame) * dof if dof > 0 else math.inf
    p_value = chi2_p_value(distance2, dof) if dof > 0 else math.nan
    d = size
    return FrameCheck(
        frame=prior.frame, distance2=distance2, dof=dof, threshold=threshold,
        p_value=p_value, moved=bool(dof > 0 and distance2 > threshold),
        translation_mm=float(np.linalg.norm(d[lengths]) * 1e3) if lengths else None,
        rotation_deg=float(math.degrees(np.linalg.norm(d[angles]))) if angles else None,
        confounded=confounded)


def check_reference(full: FitResult, priors: Sequence[FramePrior], *,
                    alpha: float = DEFAULT_ALPHA, effects: Any = None,
                    plugins: Sequence[str] = (), loss: str = "linear") -> ReferenceCheck:
    """Check every referenced frame of a fit made with `priors` (module docstring)."""
    checks = tuple(check_frame(full, prior, len(priors), alpha, effects, plugins, loss)
                   for prior in priors)
    flagged = [c for c in checks if c.moved]
    cause = None
    if flagged:  # smallest p-value; ties (p underflows to 0) by D^2 over its threshold
        cause = min(flagged, key=lambda c: (c.p_value, -c.distance2 / c.threshold)).frame
    return ReferenceCheck(alpha, checks, cause)
