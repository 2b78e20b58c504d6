"""What the plan can see: the smallest size of each candidate effect the data would find.

For a candidate's parameter k, the chi-square drop its true value s buys (first order, the
fitted parameters re-adjusting) is ``s^2 |P c_k|^2``, with c_k the whitened Jacobian column
of k at the current fit and P the projection off the fitted columns: the part of the
effect the model cannot already absorb. The test finds it with probability ``power`` at
the per-candidate significance ``alpha`` when that drop reaches the noncentrality lambda
at which a one-degree-of-freedom chi-square test at level alpha has that power. So

    minimum detectable size = sqrt(lambda) * sigma_scale / |P c_k|

in the parameter's unit (sigma_scale: the square root of the fit's chi2/dof when above 1,
the stated noise otherwise). It depends only on the design (the poses, the noise, the
model), not on the measured values: before measuring it is computed on the planned poses.
``shift`` is what that size does to the measurements: the largest change of one measured
point (m, the length axes) across the samples - "thermal_expansion below 35 um at the
flange would not be seen with these poses".

The power of the noncentral chi-square uses Patnaik's approximation (a scaled central
chi-square with the same mean and variance).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from hostpc.dataset import Dataset
from hostpc.diagnostics.candidates import (
    candidate_effects,
    candidate_start,
    evaluated_with_derivative,
)
from hostpc.diagnostics.distributions import chi2_isf, chi2_sf
from hostpc.errors import InputError
from hostpc.fitting import FitResult, analyse
from hostpc.fitting.identifiability import WEAK_SIGMA_LIMIT
from hostpc.fitting.solver import Evaluation, evaluate
from hostpc.json_object import JsonObject
from hostpc.model.effect import Effect
from hostpc.model.layout import Problem
from hostpc.model.problem import build_problem, extend_problem
from hostpc.model.registry import available_effects

DEFAULT_POWER = 0.8


def power(noncentrality: float, critical: float, dof: int = 1) -> float:
    """P(noncentral chi-square(dof, noncentrality) > critical) (Patnaik)."""
    mean, variance = dof + noncentrality, 2.0 * (dof + 2.0 * noncentrality)
    scale = variance / (2.0 * mean)
    return chi2_sf(critical / scale, mean / scale)


@functools.lru_cache(maxsize=64)
def required_noncentrality(alpha: float, target: float = DEFAULT_POWER, dof: int = 1
                           ) -> float:
    """The noncentrality at which the chi-square test at level alpha has power target.

    A bisection of ~60 power evaluations, kept per arguments: every candidate of a
    diagnosis asks it at the same threshold."""
    critical = chi2_isf(alpha, dof)
    low, high = 0.0, 1.0
    while power(high, critical, dof) < target:
        high *= 2.0
    for _ in range(60):
        middle = 0.5 * (low + high)
        low, high = (middle, high) if power(middle, critical, dof) < target else (low, middle)
    return high


UNSEEN_SHIFT = 0.05
"""m: a detectable size that moves a measured point by more than this is reported as not
seen at all (50 mm, the bound beyond which the fit holds a length as undetermined,
``hostpc.fitting.identifiability.WEAK_SIGMA_LIMIT``: far beyond any calibration)."""


PLAUSIBLE_SIZE = {**WEAK_SIGMA_LIMIT, "rad/(N m)": 1e-3, "m/N": 1e-5, "rad/rad": 0.1, "": 0.1,
                  "1": 0.1, "1/K": 1e-3, "1/s": 1e-4, "s": 1.0}
"""The largest size of a parameter, by unit, that a real robot could need calibrated: 5 deg
and 50 mm (the fit's bounds, ``hostpc.fitting.identifiability.WEAK_SIGMA_LIMIT``), a
compliance of 1e-3 rad/(N m) (0.057 deg per N m; real joints bend 1e-6..1e-4), of a
prismatic joint 1e-5 m/N (10 mm per kN; a lift axis gives 1e-7..1e-6), a coupling
or a scale of 10 %, an expansion of 1e-3 per K (80 times steel's), 1e-4 per s, a latency of
1 s. A detectable size beyond it means the poses barely move the effect (a wrist joint's
compliance with no gravity torque on it): not detectable with these poses."""


def _significant(value: float, digits: int) -> str:
    """``value`` to ``digits`` significant digits, never in exponent form (320, not 3.2e+02)."""
    return f"{float(f'{value:.{digits}g}'):g}"


def length_text(value: float, digits: int) -> str:
    """A length (m) in um below 1 mm, else in mm."""
    if value < 1e-3:
        return f"{_significant(value * 1e6, digits)} um"
    return f"{_significant(value * 1e3, digits)} mm"


@dataclass(frozen=True)
class DetectableSize:
    """The smallest value of one candidate parameter the test would find (``size``, in
    ``unit``; inf: the model absorbs it entirely) and its largest shift of a measured point
    (m)."""

    effect: str
    parameter: str
    size: float
    unit: str
    shift: float

    @property
    def limit(self) -> float:
        """The largest plausible size in this unit (``PLAUSIBLE_SIZE``; inf if unlisted)."""
        return PLAUSIBLE_SIZE.get(self.unit, math.inf)

    @property
    def seen(self) -> bool:
        """False when no size the calibration could meet would be seen: the model absorbs
        it, the size is beyond any real robot's (``PLAUSIBLE_SIZE``), or it moves a measured
        point by more than ``UNSEEN_SHIFT`` (a design that barely moves the effect at all,
        e.g. compliance on three poses)."""
        return math.isfinite(self.size) and self.size <= self.limit \
            and math.isfinite(self.shift) and self.shift <= UNSEEN_SHIFT

    @property
    def _unit(self) -> str:
        return "" if self.unit in ("", "1") else f" {self.unit}"

    @property
    def _why_not(self) -> str:
        """Why it is not detectable, with the threshold it misses (the size unseen)."""
        if not math.isfinite(self.size):
            return "the model absorbs it"
        if self.size > self.limit:
            return (f"only above {_significant(self.limit, 2)}{self._unit}, more than any "
                    "real robot's")
        return f"only by moving a measured point more than {UNSEEN_SHIFT * 1e3:.0f} mm"

    @property
    def sentence(self) -> str:
        if not self.seen:
            return f"{self.parameter} is not detectable with these poses ({self._why_not})"
        return (f"{self.parameter} below {self.size:.3g}{self._unit} "
                f"({length_text(self.shift, 3)} at the measured points) would not be seen "
                "with these poses")

    @property
    def short(self) -> str:
        """``parameter size unit (shift)``, for a list on one line."""
        if not self.seen:
            return f"{self.parameter} not detectable with these poses ({self._why_not})"
        return (f"{self.parameter} {self.size:.2g}{self._unit} "
                f"({length_text(self.shift, 2)})")

    def to_dict(self) -> JsonObject:
        return {"effect": self.effect, "parameter": self.parameter,
                "size": self.size if math.isfinite(self.size) else None,
                "unit": self.unit, "shift": self.shift if math.isfinite(self.shift) else None}


def best_seen(sizes: Sequence[DetectableSize]) -> DetectableSize:
    """The parameter of an effect the poses see best: the smallest shift among the
    detectable ones (a plausible size), else among all."""
    return min(sizes, key=lambda s: (not s.seen, s.shift))


def detectable_sizes(base: FitResult, effect: Effect, alpha: float,
                     target: float = DEFAULT_POWER) -> tuple[DetectableSize, ...]:
    """The minimum detectable size of each parameter of ``effect`` added to ``base`` at
    significance ``alpha`` (the per-candidate threshold) and power ``target``, linearised
    at the candidate fit's start (``candidate_start``: the same prediction)."""
    problem, x0, start, raw = candidate_start(base, effect)
    if raw is None:  # a large problem (not kept): the raw derivative predicted here
        start, raw = evaluated_with_derivative(problem, x0)
    scale = math.sqrt(max(base.chi2_dof, 1.0)) if base.dof > 0 else 1.0
    return _sizes(problem, start, raw, base.fixed, effect, alpha, target, scale)


def _sizes(problem: Problem, start: Evaluation, raw: np.ndarray, fixed: np.ndarray,
           effect: Effect, alpha: float, target: float, scale: float
           ) -> tuple[DetectableSize, ...]:
    """The sizes of ``effect``'s parameters in ``problem`` (the model's parameters first,
    ``fixed`` of them held) linearised at ``start`` (its whitened Jacobian; ``raw``: the
    raw derivative of the predictions there, for the lengths), at the noise ``scale``."""
    J = start.jacobian
    assert J is not None
    n_base = fixed.size
    fitted = J[:, :n_base][:, ~fixed]
    basis = np.linalg.qr(fitted)[0] if fitted.shape[1] else np.zeros((J.shape[0], 0))
    lengths = raw[:, problem.length_columns, :]
    root = math.sqrt(required_noncentrality(alpha, target))
    span = problem.layout.effect_slices[effect.name]
    units = list(effect.parameter_units(problem.context))
    sizes = []
    for index, k in enumerate(range(span.start, span.stop)):
        column = J[:, k] - basis @ (basis.T @ J[:, k])
        norm = float(np.linalg.norm(column))
        whole = float(np.linalg.norm(J[:, k]))
        size = math.inf if norm <= 1e-9 * max(whole, 1e-300) else root * scale / norm
        shift = (float(np.max(np.linalg.norm(lengths[:, :, k], axis=1))) * size
                 if math.isfinite(size) else math.inf)
        sizes.append(DetectableSize(effect.name, problem.layout.names[k], size,
                                    units[index] if index < len(units) else "", shift))
    return tuple(sizes)


def planned_sizes(design: Dataset, effects: str | Sequence[str] | None,
                  plugins: Sequence[str], alpha: float, target: float = DEFAULT_POWER
                  ) -> tuple[DetectableSize, ...]:
    """Before measuring: the best-seen parameter of each candidate effect on the planned
    poses (``design``: their nominal predictions and stated covariances), at the stated
    noise and the candidates' threshold (``candidate_sizes``); the model's parameters
    the design cannot see are held, as the fit would hold them."""
    problem = build_problem(design, effects, plugins=plugins)
    x0 = np.zeros(problem.layout.size)
    J = evaluate(problem, x0).jacobian
    assert J is not None
    fixed = analyse(J, list(problem.layout.names), list(problem.layout.units)).fixed
    registry = available_effects(tuple(plugins))
    names = candidate_effects(problem, registry)
    threshold = alpha / max(len(names), 1) / 2.0
    found = []
    for name in names:
        effect = registry[name]()
        try:
            extended = extend_problem(problem, [effect])
            start, raw = evaluated_with_derivative(extended, np.zeros(extended.layout.size))
            sizes = _sizes(extended, start, raw, fixed, effect, threshold, target, 1.0)
        except InputError:
            continue
        if sizes:
            found.append(best_seen(sizes))
    return tuple(found)


def candidate_sizes(base: FitResult, registry: Mapping[str, type[Effect]],
                    names: Sequence[str], alpha: float, target: float = DEFAULT_POWER
                    ) -> tuple[DetectableSize, ...]:
    """The best-seen parameter of each candidate (its smallest detectable shift), at the
    candidates' Bonferroni threshold ``alpha / len(names)``, halved because a candidate's
    p-value is doubled (``try_candidate``); candidates that cannot be added are left out."""
    threshold = alpha / max(len(names), 1) / 2.0
    found = []
    for name in names:
        try:
            sizes = detectable_sizes(base, registry[name](), threshold, target)
        except InputError:
            continue
        if sizes:
            found.append(best_seen(sizes))
    return tuple(found)
