"""Where does the model fail? Per-sample residuals, the worst samples, and the residuals
binned against every recorded or derived variable of the dataset contract.

A pattern is a number: for each variable the samples are split into quantile bins, and the
mean whitened residual of each bin is tested against zero (sum over bins of n_b |mean_b|^2
is chi-square with bins x m degrees of freedom if the residuals are pure noise).

A variable is tested on the samples of its group only (where it is finite: ``left.q3`` on
the left arm's samples). A categorical variable (a group label such as ``marker``: the
model context's ``categorical``) gets one bin per level, so "the residual depends on
marker" names the level whose mean residual is off (``VariablePattern.strongest_level``).
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from hostpc.diagnostics.distributions import chi2_sf

ANGLE_VARIABLE = re.compile(r"(^|\.)q\d+$")
DEFAULT_BINS = 6
WORST_COUNT = 10


def is_angle(variable: str) -> bool:
    """True for joint-angle variables (``q3``, ``left.q3``): they get harmonic modulators."""
    return bool(ANGLE_VARIABLE.search(variable))


def analysis_variables(variables: Mapping[str, np.ndarray], measured: np.ndarray,
                       raw: np.ndarray) -> dict[str, np.ndarray]:
    """The dataset's variables for residual analysis, with ``depth`` taken from the model's
    prediction (measured - residual) instead of the measurement: a regressor that carries
    the measurement's own noise correlates with the residuals and fakes a pattern.

    measured, raw: (N, m) measurements and residuals; depth is the sensor z (m = 3).
    """
    chosen = dict(variables)
    if "depth" in chosen and measured.shape[1] == 3:
        chosen["depth"] = measured[:, 2] - raw[:, 2]
    return chosen


MIN_DEFINED_SAMPLES = 8
"""A variable defined (finite) on fewer samples than this is not tested."""


def usable_variables(variables: Mapping[str, np.ndarray],
                     min_defined: int = MIN_DEFINED_SAMPLES) -> dict[str, np.ndarray]:
    """The variables to test, in contract order (as the model context lists them).

    A variable is tested on the samples where it is defined (finite): a per-chain variable
    of a two-arm dataset (``left.q3`` is NaN on the right arm's samples) is tested on its own
    arm's samples. It is kept when it is defined on at least ``min_defined`` samples (and on
    all of them when there are fewer) and varies there. The values keep their NaNs: callers
    restrict to ``np.isfinite(values)``.
    """
    usable = {}
    for name, values in variables.items():
        values = np.asarray(values, dtype=float)
        defined = np.isfinite(values)
        count = int(np.count_nonzero(defined))
        if count < min(min_defined, values.size) or count < 2:
            continue
        present = values[defined]
        if np.ptp(present) <= 1e-12 * max(1.0, float(np.max(np.abs(present)))):
            continue
        usable[name] = values
    return usable


@dataclass(frozen=True)
class SampleResidual:
    """One sample: index, raw residual norm (m), whitened norm, and its raw residual (m,)."""

    index: int
    norm: float
    whitened_norm: float
    raw: tuple[float, ...]


@dataclass(frozen=True, eq=False)  # holds arrays: compared by identity (__init__.py)
class VariablePattern:
    """Residuals binned against one variable.

    edges: (B+1,) bin edges in the variable's unit; centres, counts: (B,); mean_raw: (B, m)
    mean raw residual per bin (m); mean_whitened: (B, m); chi2, dof, p_value: the test of
    all bin means against zero; significant: p_value below the corrected threshold.
    """

    variable: str
    edges: np.ndarray
    centres: np.ndarray
    counts: np.ndarray
    mean_raw: np.ndarray
    mean_whitened: np.ndarray
    chi2: float
    dof: int
    p_value: float
    significant: bool
    #: level names of the bins of a categorical variable (one bin per level), else ()
    levels: tuple[str, ...] = ()

    @property
    def strongest_level(self) -> tuple[str, np.ndarray] | None:
        """For a categorical variable: the level whose bin contributes most to chi2, and its
        mean raw residual (m,); None for a numeric variable."""
        if not self.levels:
            return None
        contribution = self.counts * np.sum(self.mean_whitened**2, axis=1)
        level = int(np.argmax(contribution))
        return self.levels[level], self.mean_raw[level]

    @property
    def sentence(self) -> str:
        """"the residual depends on V" (for a group: and which level is off, by how much;
        the mean residual left after the fit, which absorbs part of the offset)."""
        strongest = self.strongest_level
        if strongest is None:
            return f"the residual depends on {self.variable}"
        level, mean = strongest
        return (f"the residual depends on {self.variable}: the samples of {self.variable} "
                f"{level} are off by {float(np.linalg.norm(mean)) * 1e3:.3g} mm on average")


@dataclass(frozen=True, eq=False)  # holds arrays: compared by identity (__init__.py)
class ResidualAnalysis:
    """norms: (N,) raw residual norms (m); whitened_norms: (N,); worst: the largest whitened
    residuals first; patterns: one per variable, most significant first; threshold: the
    per-test p-value threshold (alpha over the number of variables)."""

    norms: np.ndarray
    whitened_norms: np.ndarray
    worst: tuple[SampleResidual, ...]
    patterns: tuple[VariablePattern, ...]
    threshold: float


def sorted_distinct(values: np.ndarray) -> np.ndarray:
    """``np.unique(values)`` (sorted distinct values) by its sorting path: plain
    ``np.unique`` (and ``np.quantile``, which calls it) asks ``np.ma.is_masked`` first,
    and importing numpy.ma costs ``hostpc diagnose`` ~16 ms of start-up."""
    return np.unique(values, return_index=True)[0]


def quantiles(values: np.ndarray, q: np.ndarray) -> np.ndarray:
    """``np.quantile(values, q)`` of finite 1-D ``values``, the same doubles (the default
    'linear' rule: position (n - 1) q in the sorted values, interpolated between its two
    neighbours from the nearer one; a zero may differ in sign), without numpy.ma
    (``sorted_distinct``)."""
    ordered = np.sort(values)
    position = (ordered.size - 1) * q
    below = np.floor(position).astype(np.intp)
    above = below + 1
    last = position >= ordered.size - 1
    below[last] = above[last] = -1
    weight = position - below
    low, high = ordered[below], ordered[above]
    step = high - low
    return np.where(weight >= 0.5, high - step * (1 - weight), low + step * weight)


def _bins(values: np.ndarray, n_bins: int, categorical: bool = False
          ) -> tuple[np.ndarray, np.ndarray]:
    """Quantile bin edges and the bin index of every value (discrete values, and every level
    of a categorical variable: one bin each)."""
    distinct = sorted_distinct(values)
    if distinct.size <= n_bins or categorical:
        edges = np.concatenate([distinct[:1], (distinct[:-1] + distinct[1:]) / 2, distinct[-1:]])
        index = np.searchsorted(distinct, values)
        return edges, index
    edges = sorted_distinct(quantiles(values, np.linspace(0.0, 1.0, n_bins + 1)))
    index = np.clip(np.searchsorted(edges, values, side="right") - 1, 0, edges.size - 2)
    return edges, index


def bin_pattern(variable: str, values: np.ndarray, raw: np.ndarray, whitened: np.ndarray,
                n_bins: int, threshold: float, levels: tuple[str, ...] | None = None
                ) -> VariablePattern:
    """Bin the residuals (N, m) against one variable (N,) and test the bin means, on the
    samples where the variable is defined (finite). levels: the level names of a
    categorical variable (values are level indices): one bin per level present."""
    defined = np.isfinite(values)
    if not np.all(defined):
        values, raw, whitened = values[defined], raw[defined], whitened[defined]
    edges, index = _bins(values, n_bins, categorical=levels is not None)
    n_used = edges.size - 1
    m = raw.shape[1]
    counts = np.bincount(index, minlength=n_used).astype(float)
    keep = counts > 0
    sums_raw = np.stack([np.bincount(index, raw[:, k], n_used) for k in range(m)], axis=1)
    sums_white = np.stack([np.bincount(index, whitened[:, k], n_used) for k in range(m)], axis=1)
    safe = np.where(keep, counts, 1.0)[:, None]
    mean_raw = sums_raw / safe
    mean_white = sums_white / safe
    chi2 = float(np.sum(counts[:, None] * mean_white**2))
    dof = int(np.count_nonzero(keep) * m)
    p_value = chi2_sf(chi2, dof) if dof else 1.0
    centres = np.array([values[index == b].mean() if keep[b] else np.nan for b in range(n_used)])
    names = () if levels is None else tuple(levels[int(c)] for c in sorted_distinct(values))
    return VariablePattern(variable, edges, centres, counts.astype(int), mean_raw, mean_white,
                           chi2, dof, p_value, bool(p_value < threshold), names)


def analyse_residuals(raw: np.ndarray, whitened: np.ndarray,
                      variables: Mapping[str, np.ndarray], alpha: float,
                      n_bins: int = DEFAULT_BINS, worst_count: int = WORST_COUNT,
                      length_columns: np.ndarray | None = None,
                      categorical: Mapping[str, tuple[str, ...]] | None = None
                      ) -> ResidualAnalysis:
    """Per-sample norms, the worst samples and the binned pattern of every variable.

    raw, whitened: (N, m) residuals (measured - predicted) of the fitted model;
    length_columns: the components that are lengths (the norms in m; None: all);
    categorical: the group-label variables and their level names (one bin per level).
    """
    norms = np.linalg.norm(raw if length_columns is None else raw[:, length_columns], axis=1)
    whitened_norms = np.linalg.norm(whitened, axis=1)
    order = np.argsort(-whitened_norms)[:worst_count]
    worst = tuple(
        SampleResidual(int(i), float(norms[i]), float(whitened_norms[i]),
                       tuple(float(v) for v in raw[i]))
        for i in order
    )
    usable = usable_variables(variables)
    threshold = alpha / max(len(usable), 1)
    groups = dict(categorical or {})
    patterns = [bin_pattern(name, values, raw, whitened, n_bins, threshold, groups.get(name))
                for name, values in usable.items()]
    patterns.sort(key=lambda p: p.p_value)
    return ResidualAnalysis(norms, whitened_norms, worst, tuple(patterns), threshold)
