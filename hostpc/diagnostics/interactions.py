"""Effect-agnostic search: which parameter varies with which variable?

A score (added-variable) test on the current fit. For model parameter k with whitened
Jacobian column J_k (N*m,) and a recorded variable v, the hypothesis "parameter k varies
with v" adds the columns ``J_k * f(v)`` with f = the centred variable, and for joint angles
also sin v and cos v (one harmonic); for a group label (a categorical variable such as
``marker``) f = the centred indicator of each level ("k differs per marker"). A variable
that exists on a group of samples only (NaN elsewhere) is tested on that group. The already-
fitted columns are projected out; the statistic is the chi-square drop the added columns
would buy at first order, ``s = |Q_z^T r|^2`` (Q_z an orthonormal basis of the projected
columns, r the whitened residuals), turned into an F-test against the residual variance (so
a wrong overall noise scale does not matter). ``score`` is -log10 of its p-value;
significance is Bonferroni corrected over all (parameter, variable) pairs tested. A
significant "per level" pair also carries the parameter's value on each level's samples
(first order, against the mean over the levels): which group is off, and by how much.

The parameters tested are those of the model plus, when the model has no ``geometry``
effect, the DH/MDH table deltas (named ``geometry.<name>``), so a drifting link length is
found even before geometry is modelled. Parameters are columns of the Jacobian, so this
works for any effect, method and measurement size.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np

from hostpc.diagnostics.candidates import candidate_start
from hostpc.diagnostics.distributions import f_logsf
from hostpc.diagnostics.residual_analysis import is_angle, sorted_distinct, usable_variables
from hostpc.errors import InputError
from hostpc.fitting import FitResult
from hostpc.fitting.solver import evaluate
from hostpc.json_object import JsonObject
from hostpc.model.effects import Geometry

RANK_TOLERANCE = 1e-6


@dataclass(frozen=True)
class Interaction:
    """"``parameter`` varies with ``variable``": score = -log10(p), chi2 = the statistic
    (first-order chi-square drop), dof = columns tested, p_value, significant,
    basis: "linear", "linear+harmonic" or "per level" (a group label); fitted: whether
    the parameter is in the model; unit: the parameter's SI unit; level_shifts (a
    significant "per level" pair only): (level name, the parameter's first-order change on
    that level's samples against the mean over the levels, in ``unit``), in level order."""

    parameter: str
    variable: str
    score: float
    chi2: float
    dof: int
    p_value: float
    significant: bool
    basis: str
    fitted: bool
    equivalent: tuple[str, ...] = ()
    unit: str = ""
    level_shifts: tuple[tuple[str, float], ...] = ()

    @property
    def sentence(self) -> str:
        if self.equivalent:
            return (f"{self.parameter} (or equally {', '.join(self.equivalent)}) varies with "
                    f"{self.variable}")
        return f"{self.parameter} varies with {self.variable}"

    def to_dict(self) -> JsonObject:
        return {
            "parameter": self.parameter, "variable": self.variable, "score": self.score,
            "chi2": self.chi2, "dof": self.dof, "p_value": self.p_value,
            "significant": self.significant, "basis": self.basis, "fitted": self.fitted,
            "equivalent": list(self.equivalent), "unit": self.unit,
            "level_shifts": [[level, shift] for level, shift in self.level_shifts],
        }


def modulators(name: str, values: np.ndarray, categorical: bool = False
               ) -> tuple[np.ndarray, str]:
    """(N, g) functions of one variable that a parameter may vary with, and their name.

    Where the variable is not defined (NaN: the other arm's samples of a per-chain variable)
    the functions are 0: the parameter is tested for varying on the samples that have it;
    the functions are centred over those samples. A categorical variable (level indices)
    gives one centred indicator per level ("per level": rank levels - 1)."""
    defined = np.isfinite(values)
    present = values[defined]
    if categorical:
        indicators = (present[:, None] == sorted_distinct(present)[None, :]).astype(float)
        F = np.zeros((values.size, indicators.shape[1]))
        F[defined] = indicators - indicators.mean(axis=0)
        return F, "per level"
    centred = present - present.mean()
    scale = float(np.std(centred)) or 1.0
    columns = [centred / scale]
    basis = "linear"
    if is_angle(name):
        for function in (np.sin, np.cos):
            column = function(present)
            columns.append(column - column.mean())
        basis = "linear+harmonic"
    F = np.zeros((values.size, len(columns)))
    F[defined] = np.stack(columns, axis=1)
    return F, basis


def _geometry_columns(result: FitResult) -> tuple[list[str], list[str], np.ndarray] | None:
    """(names, units, whitened Jacobian columns) of the DH/MDH deltas at the fit, if
    geometry is not fitted."""
    problem = result.problem
    if "geometry" in problem.effect_names:
        return None
    try:  # at the geometry candidate's start: the same evaluation, shared
        extended, _, start, _ = candidate_start(result, Geometry())
    except InputError:  # a method without a geometry effect
        return None
    J = start.jacobian
    assert J is not None
    span = extended.layout.effect_slices["geometry"]
    columns = J[:, span]
    # a table delta the model already spans (d1 is target.z) would only repeat that name
    J_free = J[:, : result.x.size][:, ~result.fixed]
    Q = np.linalg.qr(J_free)[0] if J_free.shape[1] else np.zeros((J.shape[0], 0))
    outside = np.linalg.norm(columns - Q @ (Q.T @ columns), axis=0)
    keep = outside > 1e-6 * np.maximum(np.linalg.norm(columns, axis=0), 1e-300)
    names = [n for n, k in zip(extended.layout.names[span], keep, strict=True) if k]
    units = [u for u, k in zip(extended.layout.units[span], keep, strict=True) if k]
    return names, units, columns[:, keep]


def search_interactions(result: FitResult, variables: Mapping[str, np.ndarray], alpha: float,
                        include_geometry: bool = True) -> tuple[tuple[Interaction, ...], int]:
    """Every (parameter, variable) pair scored, best first; and the number of tests."""
    problem = result.problem
    evaluation = evaluate(problem, result.x)
    J = evaluation.jacobian
    assert J is not None
    n_samples, m = problem.measured.shape
    row_weight = np.repeat(np.sqrt(result.weights), m)
    r = evaluation.whitened.ravel() * row_weight
    names = list(problem.layout.names)
    units = list(problem.layout.units)
    fitted = [True] * len(names)
    columns = J
    if include_geometry:
        extra = _geometry_columns(result)
        if extra is not None:
            names += extra[0]
            units += extra[1]
            fitted += [False] * len(extra[0])
            columns = np.concatenate([J, extra[2]], axis=1)
    columns = columns * row_weight[:, None]
    J_free = J[:, ~result.fixed] * row_weight[:, None]
    Q = np.linalg.qr(J_free)[0] if J_free.shape[1] else np.zeros((r.size, 0))
    chi2 = float(r @ r)
    dof_fit = r.size - J_free.shape[1]
    norms = np.linalg.norm(columns, axis=0)
    alive = norms > 1e-12 * max(float(norms.max(initial=0.0)), 1e-300)
    alive[: result.fixed.size] &= ~result.fixed  # held (unidentifiable) parameters: not tested
    usable = usable_variables(variables)
    categorical = problem.context.categorical
    pairs: list[tuple[str, str, float, int, str, bool, tuple[str, ...]]] = []
    for variable, values in usable.items():
        F, basis = modulators(variable, values, variable in categorical)
        F_rows = np.repeat(F, m, axis=0)  # (N*m, g)
        listed = _ListedSpans()
        for k, (statistic, rank, U) in _statistics(columns, np.flatnonzero(alive), F_rows,
                                                    Q, r):
            same = listed.find(statistic, U)
            if same is not None:  # one indistinguishable combination: one entry
                entry = pairs[same]
                pairs[same] = entry[:6] + (entry[6] + (names[k],),)
                continue
            if U is not None:
                listed.add(statistic, U, len(pairs))
            pairs.append((names[k], variable, statistic, rank, basis, fitted[k], ()))
    n_tests = len(pairs)
    threshold = alpha / max(n_tests, 1)
    statistics = np.array([p[2] for p in pairs])
    ranks = np.array([p[3] for p in pairs])
    testable = (ranks > 0) & (dof_fit - ranks > 0)
    safe_rank = np.maximum(ranks, 1)
    remaining = np.maximum(chi2 - statistics, 1e-300) / np.maximum(dof_fit - safe_rank, 1)
    log_p = np.where(testable, f_logsf(statistics / safe_rank / remaining, safe_rank,
                                       np.maximum(dof_fit - safe_rank, 1)), 0.0)
    log_p = np.where(np.isfinite(log_p), log_p, -300.0 * math.log(10.0))
    column_of = {name: k for k, name in enumerate(names)}
    found = [
        Interaction(parameter, variable, float(-lp / math.log(10.0)) + 0.0, float(s), int(g),
                    float(math.exp(lp)), bool(math.exp(lp) < threshold), basis, is_fitted,
                    equivalent, units[column_of[parameter]])
        for (parameter, variable, s, g, basis, is_fitted, equivalent), lp
        in zip(pairs, log_p.tolist(), strict=True)  # Python floats: the same digits, faster
    ]
    for i, interaction in enumerate(found):
        if interaction.significant and interaction.basis == "per level":
            values = usable[interaction.variable]
            column = columns[:, column_of[interaction.parameter]]
            found[i] = replace(interaction, level_shifts=level_shifts(
                column, values, categorical[interaction.variable], m, Q, r))
    found.sort(key=lambda i: (-i.score, i.parameter, i.variable))
    return tuple(found), n_tests


def level_shifts(column: np.ndarray, codes: np.ndarray, levels: Sequence[str], m: int,
                 Q: np.ndarray, r: np.ndarray) -> tuple[tuple[str, float], ...]:
    """The parameter's first-order value on each level's samples, against the mean over
    the levels: the least-squares change (minimum norm, so the changes sum to zero) along
    its added "per level" columns, fitted columns Q projected out, that removes the
    residuals. The column is d(r)/dx of r = W (measured - predicted), so that change is
    ``-lstsq(Z, r)``: a level measured as if the parameter were larger gets a positive
    shift.

    column: the parameter's whitened Jacobian column (N*m,); codes: the level index of
    each sample (N,), NaN where it has none; levels: the level names; m: the measurement
    size; Q: (N*m, k) orthonormal basis of the fitted columns; r: whitened residuals
    (N*m,). Returns (level name, change in the parameter's unit), one per level present."""
    F, _ = modulators("", codes, categorical=True)
    Z = column[:, None] * np.repeat(F, m, axis=0)
    Z = Z - Q @ (Q.T @ Z)
    coefficients = -np.linalg.lstsq(Z, r, rcond=None)[0]
    present = sorted_distinct(codes[np.isfinite(codes)])
    return tuple((levels[int(code)], float(c)) for code, c in
                 zip(present, coefficients, strict=True))


#: values of the added columns of one batch of parameters (rows x parameters x g; 4 MB)
BATCH_ELEMENTS = 1 << 19


def _statistics(columns: np.ndarray, tested: np.ndarray, F_rows: np.ndarray, Q: np.ndarray,
                r: np.ndarray) -> Iterator[tuple[int, tuple[float, int, np.ndarray | None]]]:
    """Per tested parameter k (in order): k and (first-order chi-square drop, rank,
    orthonormal basis) of its added columns ``J_k * F`` (rows, g) with the fitted columns Q
    projected out, for the residuals r. Directions that projection all but removed (singular
    values below RANK_TOLERANCE times the columns' norm before projection) are rounding
    noise, not evidence. The parameters go in batches (one projection and one stacked SVD
    per batch of at most BATCH_ELEMENTS values: memory stays bounded in N)."""
    n_rows, g = F_rows.shape
    batch = max(1, BATCH_ELEMENTS // max(n_rows * g, 1))
    for start in range(0, tested.size, batch):
        ks = tested[start:start + batch]
        Z = columns[:, ks, None] * F_rows[:, None, :]  # (rows, K, g)
        sizes = np.sqrt(np.einsum("rkg,rkg->k", Z, Z))
        flat = Z.reshape(n_rows, -1)
        flat = flat - Q @ (Q.T @ flat)
        if n_rows == 0 or g == 0:
            for k in ks:
                yield int(k), (0.0, 0, None)
            continue
        stacked = np.ascontiguousarray(flat.reshape(n_rows, ks.size, g).transpose(1, 0, 2))
        U, s, _ = np.linalg.svd(stacked, full_matrices=False)  # (K, rows, g), (K, g)
        ranks = np.sum(s > RANK_TOLERANCE * sizes[:, None], axis=1)
        ranks[sizes <= 0.0] = 0
        projected = np.einsum("krg,r->kg", U, r) ** 2
        drops = np.sum(np.where(np.arange(g) < ranks[:, None], projected, 0.0), axis=1)
        for i, (k, rank, drop) in enumerate(zip(ks.tolist(), ranks.tolist(), drops.tolist(),
                                                strict=True)):
            yield k, ((drop, rank, U[i, :, :rank]) if rank else (0.0, 0, None))


class _ListedSpans:
    """The spans listed so far for one variable: a new one with the same statistic (to
    1e-8) and the same span is the same hypothesis (spans compared only then: cheap)."""

    def __init__(self) -> None:
        self.statistics: list[float] = []  # sorted
        self.entries: list[tuple[int, np.ndarray]] = []  # (pair index, basis), same order

    def find(self, statistic: float, U: np.ndarray | None) -> int | None:
        """The pair index of the first listed span equal to U's, or None."""
        tolerance = 1e-8 * max(statistic, 1e-12)
        low = bisect.bisect_left(self.statistics, statistic - tolerance)
        high = bisect.bisect_right(self.statistics, statistic + tolerance)
        if low == high:  # no listed span has this statistic (most tests)
            return None
        for index, basis in sorted(self.entries[low:high], key=lambda e: e[0]):
            if _same_span(basis, U):
                return index
        return None

    def add(self, statistic: float, U: np.ndarray, index: int) -> None:
        at = bisect.bisect_right(self.statistics, statistic)
        self.statistics.insert(at, statistic)
        self.entries.insert(at, (index, U))


def _same_span(a: np.ndarray, b: np.ndarray | None, tolerance: float = 1e-6) -> bool:
    """Whether two orthonormal bases span the same space: the two hypotheses cannot be told
    apart by any data of this design (one combination of parameters)."""
    if b is None or a.shape[1] != b.shape[1]:
        return False
    return bool(np.linalg.norm(b - a @ (a.T @ b)) < tolerance * np.sqrt(b.shape[1]))
