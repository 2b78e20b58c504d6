"""Which parameters the data can separate, and a gauge for those it cannot.

The whitened Jacobian's columns are normalised (each parameter measured by its own effect on
the data), then its singular values give the rank. Each direction of the null space is a
combination of parameters that leaves every measurement unchanged. We fix one parameter per
null direction (held at its start value, i.e. nominal) so the fit cannot drift along it, and
say in words which parameters could not be separated.

Which parameter to hold: a pivoted QR of the null basis picks parameters that span it
(`pivoted_columns`: LAPACK's dgeqp3 column choice, in numpy),
preferring (in order) geometry deltas, joint offsets, other effects, and frames last, so a
frame absorbs what cannot be told apart and no unobservable zero offset is ever pushed.
"""

from __future__ import annotations

from collections.abc import Collection, Sequence
from dataclasses import dataclass

import numpy as np

from hostpc.json_object import JsonObject
from hostpc.model.registry import builtin_effects

RELATIVE_RANK_TOLERANCE = 1e-7
NEAR_TIE = 1e-9
"""Column norms within this (relative) of the largest are a tie: the first parameter wins."""
MIN_GAUGE_SPAN = 0.2
FIX_PRIORITY = {"geometry": 3, "joint_offsets": 2}


@dataclass(frozen=True)
class NullDirection:
    """A combination of parameters the data cannot see.

    fixed: the parameter held at its start value for this direction;
    parameters / coefficients: the combination (fixed parameter first, coefficient 1; the
    others in their own SI units per unit of the fixed parameter); description: in words.
    """

    fixed: str
    parameters: tuple[str, ...]
    coefficients: tuple[float, ...]
    description: str

    def to_dict(self) -> JsonObject:
        return {
            "fixed": self.fixed,
            "parameters": list(self.parameters),
            "coefficients": list(self.coefficients),
            "description": self.description,
        }


@dataclass(frozen=True)
class Identifiability:
    """rank of the normalised whitened Jacobian, its singular values (descending, relative
    to the largest), condition number of the free part, fixed mask (P,), null directions."""

    rank: int
    singular_values: np.ndarray
    condition_number: float
    fixed: np.ndarray
    null_directions: tuple[NullDirection, ...]


def builtin_frame_names() -> frozenset[str]:
    """The frames with a built-in frame effect (those of hostpc.model.effects and the ones
    the built-in kinds declare): what `analyse` holds last when not told the frames."""
    return frozenset(name for name, cls in builtin_effects().items() if cls.hook == "frame")


def _priority(name: str, frames: Collection[str]) -> int:
    effect = name.split(".", 1)[0]
    if effect in FIX_PRIORITY:
        return FIX_PRIORITY[effect]
    return 0 if effect in frames else 1


def _describe(names: Sequence[str], units: Sequence[str], fixed: int, vector: np.ndarray,
              frame_names: Collection[str]) -> NullDirection:
    order = [fixed] + [k for k in np.argsort(-np.abs(vector)) if k != fixed]
    participants = [k for k in order if k == fixed or abs(vector[k]) > 1e-3 * abs(vector[fixed])]
    coefficients = tuple(float(vector[k] / vector[fixed]) for k in participants)
    others = [names[k] for k in participants[1:]]
    if others:
        listed = ", ".join(others[:4]) + (f" and {len(others) - 4} more" if len(others) > 4 else "")
        terms = ", ".join(
            f"{coefficients[i]:+.3g} {units[participants[i]]}/{units[fixed]} {names[k]}"
            for i, k in enumerate(participants[1:5], start=1)
        )
        frames = sorted({names[k].split(".")[0] for k in participants[1:]} & set(frame_names))
        advice = (f"; to determine it, mark {' or '.join(frames)} as known or add a reference"
                  if frames else "; add poses or a reference that separate them")
        text = (f"{names[fixed]} and {listed} are not separable (changing {names[fixed]} by 1 "
                f"together with {terms} leaves every measurement unchanged): "
                f"{names[fixed]} held at its nominal value{advice}")
    else:
        text = (f"{names[fixed]} has no effect on these measurements: held at its nominal value")
    return NullDirection(names[fixed], tuple(names[k] for k in participants), coefficients, text)


def pivoted_columns(matrix: np.ndarray) -> list[int]:
    """The first min(M, P) column pivots of a QR with column pivoting of matrix (M, P),
    in order: the columns `scipy.linalg.qr(matrix, pivoting=True)` puts first, except on
    ties.

    The rule of LAPACK's dgeqp3: at each step the column whose part outside the span of
    the columns chosen so far is largest (here by Gram-Schmidt on the few rows of a null
    basis: that part's norm is what dgeqp3's downdated norms estimate). Norms within
    NEAR_TIE of the largest are a tie, and the column listed first wins: LAPACK breaks such
    ties (equal norms in exact arithmetic, e.g. the symmetric participation of two DH
    deltas in a null direction) by its round-off, so its choice depended on the BLAS
    build; this one does not. Written out because scipy.linalg costs ~0.15 s to import
    (its array-API layer), more than `hostpc diagnose` needs for everything else."""
    rest = np.array(matrix, dtype=float)
    rows, cols = rest.shape
    open_ = np.ones(cols, dtype=bool)
    chosen: list[int] = []
    for _ in range(min(rows, cols)):
        norms = np.where(open_, np.sqrt(np.einsum("ij,ij->j", rest, rest)), -1.0)
        best = norms.max()
        pick = int(np.flatnonzero(norms >= best * (1.0 - NEAR_TIE))[0])
        chosen.append(pick)
        open_[pick] = False
        if best > 0.0:
            direction = rest[:, pick] / best
            rest -= np.outer(direction, direction @ rest)
    return chosen


def analyse(jacobian: np.ndarray, names: Sequence[str], units: Sequence[str],
            tolerance: float = RELATIVE_RANK_TOLERANCE,
            frames: Collection[str] | None = None) -> Identifiability:
    """Rank, null directions and the gauge (fixed mask) for a whitened Jacobian (M, P).

    frames: the effects that are frames (held last; default: `builtin_frame_names`; a fit
    passes its problem's own)."""
    frame_names: Collection[str] = builtin_frame_names() if frames is None else frames
    n_params = jacobian.shape[1]
    norms = np.linalg.norm(jacobian, axis=0)
    dead = norms <= 1e-12 * max(float(norms.max(initial=0.0)), 1e-300)
    scale = np.where(dead, 1.0, norms)
    Jn = np.where(dead[None, :], 0.0, jacobian / scale)
    if n_params == 0:
        return Identifiability(0, np.zeros(0), 1.0, np.zeros(0, bool), ())
    _, s, Vt = np.linalg.svd(Jn, full_matrices=Jn.shape[0] < n_params)
    s_full = np.zeros(n_params)
    s_full[: s.size] = s
    s_rel = s_full / max(s_full[0], 1e-300)
    rank = int(np.sum(s_rel > tolerance))
    null_basis = Vt[rank:].T  # (P, k) in normalised coordinates
    fixed = np.zeros(n_params, dtype=bool)
    directions: list[NullDirection] = []
    if null_basis.shape[1]:
        participation = np.linalg.norm(null_basis, axis=1)
        # prefer by priority only among parameters that take a real part in the null space
        strong = participation >= 0.1 * participation.max()
        priority = np.array([_priority(n, frame_names) for n in names], dtype=float)
        weight = np.where(strong, 10.0**priority, 1e-3)
        chosen = pivoted_columns(null_basis.T * weight[None, :])
        block = null_basis[chosen, :]
        # the basis is orthonormal: the held set spans the null space well when the block's
        # smallest singular value is not small; otherwise fall back to plain pivoting
        if np.linalg.svd(block, compute_uv=False).min() < MIN_GAUGE_SPAN:
            chosen = pivoted_columns(null_basis.T)
            block = null_basis[chosen, :]
        # one null vector per fixed parameter: 1 on it, 0 on the other fixed ones
        combos = null_basis @ np.linalg.inv(block)  # (P, k), normalised coordinates
        physical = combos / scale[:, None]
        for column, index in enumerate(chosen):
            fixed[index] = True
            directions.append(_describe(names, units, int(index), physical[:, column],
                                        frame_names))
    free = ~fixed
    if not np.any(fixed):
        s_free = s_full
    else:
        s_free = np.linalg.svd(Jn[:, free], compute_uv=False) if np.any(free) else np.ones(1)
    condition = float(s_free[0] / max(s_free[-1], 1e-300))
    return Identifiability(rank, s_rel, condition, fixed, tuple(directions))


WEAK_SIGMA_LIMIT = {"rad": float(np.radians(5.0)), "m": 0.05}
"""A parameter whose sigma (from the data at the measured noise, at the start) exceeds this
bound per unit is not determined by the data, though not exactly unobservable: 5 deg for an
angle, 50 mm for a length, far beyond any correction a calibration makes and far beyond
what a determined parameter's sigma is (micrometres, thousandths of a degree)."""


def hold_weak_parameters(jacobian: np.ndarray, prior_rows: np.ndarray,
                         ident: Identifiability, names: Sequence[str], units: Sequence[str],
                         noise_scale: float = 1.0) -> Identifiability:
    """`ident` with every weakly determined parameter held as well (the stated rule: a free
    parameter whose sigma from `jacobian` (M, P) and `prior_rows` (K, P) exceeds
    ``WEAK_SIGMA_LIMIT`` of its unit), so the solver cannot wander along a direction the
    data barely sees. Greedy: the parameter furthest beyond its bound is held, the sigmas
    recomputed, until every free one is within. Each held one is a NullDirection saying so
    in words.

    noise_scale: the measured noise over the stated one (sqrt(chi2/dof) of a fit, see
    ``hostpc.fitting.fitting``): the measurement rows count with the noise the data shows,
    the prior rows with their own stated sigma, so the decision does not depend on a
    uniform stated sigma (docs/fitting.md)."""
    if noise_scale != 1.0:
        jacobian = jacobian / noise_scale
    limits = np.array([WEAK_SIGMA_LIMIT.get(unit, np.inf) for unit in units])
    if not np.all(np.isfinite(jacobian)) or not np.any(np.isfinite(limits)):
        return ident
    # the normal matrix once (one BLAS product, P x P): every later step is on its blocks
    normal = jacobian.T @ jacobian
    if prior_rows.size:
        normal = normal + prior_rows.T @ prior_rows
    fixed = ident.fixed.copy()
    directions = list(ident.null_directions)
    while np.any(~fixed):
        free = np.flatnonzero(~fixed)
        block = normal[np.ix_(free, free)]
        norms = np.sqrt(np.maximum(np.diag(block), 1e-300))
        values, vectors = np.linalg.eigh(block / np.outer(norms, norms))
        keep = values > max(float(values[-1]), 1e-300) * 1e-14
        sigma = np.sqrt(np.sum(vectors[:, keep] ** 2 / values[keep], axis=1)) / norms
        ratio = sigma / limits[free]
        worst = int(np.argmax(ratio))
        if not ratio[worst] > 1.0:
            break
        index = int(free[worst])
        fixed[index] = True
        limit_text = (f"{np.degrees(limits[index]):.0f} deg" if units[index] == "rad"
                      else f"{limits[index] * 1e3:.0f} mm")
        shown = (f"{np.degrees(sigma[worst]):.3g} deg" if units[index] == "rad"
                 else f"{sigma[worst] * 1e3:.3g} mm")
        if noise_scale != 1.0:
            shown += " at the measured noise"
        directions.append(NullDirection(
            names[index], (names[index],), (1.0,),
            f"the data does not determine {names[index]} (sigma {shown}, beyond the "
            f"{limit_text} a determined parameter never reaches): held at its nominal value; "
            "add poses that move it, a prior, or hold it with --hold"))
    if len(directions) == len(ident.null_directions):
        return ident
    return Identifiability(ident.rank, ident.singular_values, ident.condition_number, fixed,
                           tuple(directions))
