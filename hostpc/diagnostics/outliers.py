"""Is one sample, or one pose, an outlier? A Bonferroni-corrected test of the largest
leave-one-out residual, so one bad measurement is named instead of being blamed on a missing
effect.

For sample i with whitened residual r_i (m,) and the block H_ii (m, m) of the hat matrix of
the (robust-weighted) whitened Jacobian, the residual it would have if the fit had not seen
it is e_i = (I - H_ii)^-1 r_i (exact for a linear model), and

    d_i^2 = r_i^T (I - H_ii)^-1 r_i

is chi-square with m degrees of freedom in units of the stated noise. The test is
scale-free, like the candidate tests: the noise level is estimated from the other samples
(``S_(i) = chi2 - d_i^2`` over ``dof - m``), and ``F_i = (d_i^2 / m) / (S_(i) / (dof - m))``
is F(m, dof - m) distributed if sample i is as good as the rest. A covariance that is wrong
by a constant factor therefore flags no sample.

A pose that repeats a measurement (the same pose and marker read more than once, a copied
row included: ``repeats.repeat_pairs``) is also tested as one: the whole pose left out (i
and r_i above become its samples and rows), so no copy predicts another; the fit that has
seen one copy predicts the other, so the one-sample test cannot see a bad pose read twice
(an exact duplicate row least of all). A pose read twice is one pose, not two witnesses
for it: repeats that agree show that the instrument repeated the reading, not that the
pose is good, and whatever is wrong at a pose (a bumped target, a wrong joint reading, the
model's own misfit there) repeats with it. So the pose is judged as one reading: its d^2
and its dimensions are divided by the number of times it was read (a pose read k times
with d^2 = k D^2 over k m dimensions tests as D^2 over m, the test of one sample), and a
pose the model misses by 2.5 mm at 0.6 mm of noise is no more an outlier for being read
twice than once. A
pose of several markers read once needs no such test: each marker is a point of its own,
which the others do not predict, and the one-sample test names them (as one pose, in the
text); tested as one, such poses would mostly be blamed for the model's own misfit where
it is largest (FIGAROH's TIAGo, 34 poses of 3 markers: 3 poses named against the offsets
model, one of which the geometry explains). The family is every sample plus every
repeated pose: a sample or pose is an outlier when its p-value is below ``alpha`` over that
count (Bonferroni, so ``alpha`` is family-wise); a pose named so names every sample of it.

A pose measured twice is tested directly first (``repeats``): a pair of repeats that
disagrees beyond the stated noise names its worse-fitted sample. Outliers are found one at
a time: the most significant sample or pose is set aside, the model is refitted without
it, and the test is repeated on the rest (a gross outlier drags the fit and would otherwise
hide, or fake, others), until ``max(1, N // 10)`` samples are set aside.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from hostpc.diagnostics.distributions import f_sf
from hostpc.diagnostics.repeats import check_repeats, measured_identity, repeat_pairs
from hostpc.fitting import FitResult
from hostpc.fitting.folds import pose_groups
from hostpc.fitting.solver import evaluate
from hostpc.json_object import JsonObject
from hostpc.model.layout import Problem

#: directions of a sample's residual that its own leverage fixes (1 - h below this) are
#: not testable: the fit reproduces them whatever the measurement says
LEVERAGE_TOLERANCE = 1e-6
#: at most this fraction of the samples is set aside as outliers (at least one)
MAX_OUTLIER_FRACTION = 0.1


@dataclass(frozen=True)
class Outlier:
    """One outlier: ``sample`` its index in the dataset; ``sigma`` the whitened norm of its
    leave-one-out residual (units of the stated noise, sqrt of chi-square with m dof);
    ``p_value`` of its scale-free test before the Bonferroni correction."""

    sample: int
    sigma: float
    p_value: float
    #: which test named it: "leave-one-out"; "pose" (every sample of a pose read more than
    #: once, left out together; ``sigma`` is the sample's own residual had the fit not seen
    #: the pose, ``p_value`` the pose's); or "repeat" (a pose
    #: measured twice whose measurements disagree beyond the noise: ``repeats``; the sample
    #: of the pair the fit explains worse)
    test: str = "leave-one-out"

    def to_dict(self) -> JsonObject:
        return {"sample": self.sample, "sigma": self.sigma, "p_value": self.p_value,
                "test": self.test}


@dataclass(frozen=True, eq=False)  # holds arrays: compared by identity (__init__.py)
class DeletionStatistics:
    """Per-sample leave-one-out statistics of one fit (arrays of length N).

    d2: r_i^T (I - H_ii)^-1 r_i (chi-square, stated-noise units); dfn: the testable
    dimensions of each sample (m unless its own leverage fixes some); p_value: the
    scale-free F-test (1 where not testable)."""

    d2: np.ndarray
    dfn: np.ndarray
    p_value: np.ndarray


@dataclass(frozen=True)
class _Design:
    """What every leave-out test of one fit needs: Q (N, m, k) the orthonormal basis of the
    (robust-weighted) whitened Jacobian's free columns, per sample; whitened (N, m); the
    robust weights (N,); the weighted chi2 and the degrees of freedom."""

    Q: np.ndarray
    whitened: np.ndarray
    weights: np.ndarray
    chi2: float
    dof: int


def _design(result: FitResult) -> _Design | None:
    """The fit's ``_Design``; None where the Jacobian or the residuals are not finite."""
    problem = result.problem
    n_samples, m = problem.measured.shape
    evaluation = evaluate(problem, result.x)
    J = evaluation.jacobian
    assert J is not None
    weights = np.asarray(result.weights, dtype=float)
    row_weight = np.repeat(np.sqrt(weights), m)
    J_free = J[:, ~result.fixed] * row_weight[:, None]
    whitened = evaluation.whitened
    if not (np.all(np.isfinite(J_free)) and np.all(np.isfinite(whitened))):
        return None
    if J_free.shape[1]:
        Q = np.linalg.qr(J_free)[0].reshape(n_samples, m, -1)
    else:
        Q = np.zeros((n_samples, m, 0))
    return _Design(Q, whitened, weights,
                   float(np.sum(weights * np.sum(whitened**2, axis=1))),
                   whitened.size - J_free.shape[1])


def _left_out(design: _Design, members: np.ndarray, reads: np.ndarray | None = None
              ) -> DeletionStatistics:
    """The leave-out statistics of each row of ``members`` (G, s): sample indices left out
    together (s = 1: one sample; more: one pose), as in the module doc; reads (G,): how
    many times each pose was read (its d2 and dimensions are those of one reading)."""
    n_groups, size = members.shape
    m = design.whitened.shape[1]
    Q = design.Q[members].reshape(n_groups, size * m, -1)
    H = np.einsum("nik,njk->nij", Q, Q)
    h, V = np.linalg.eigh(H)  # (G, s m), (G, s m, s m)
    keep = (1.0 - h) > LEVERAGE_TOLERANCE
    r = design.whitened[members].reshape(n_groups, size * m)
    projected = np.einsum("nji,nj->ni", V, r)  # V^T r per group
    d2 = np.sum(np.where(keep, projected**2 / np.where(keep, 1.0 - h, 1.0), 0.0), axis=1)
    dfn = keep.sum(axis=1)
    dfd = design.dof - dfn
    rest = design.chi2 - np.mean(design.weights[members], axis=1) * d2
    if reads is not None:  # one pose, one witness: the mean reading's share, m per read
        d2 = d2 / reads
        dfn = np.maximum(np.rint(dfn / reads).astype(np.int64), 1)
    testable = (dfn > 0) & (dfd > 0) & (rest > 1e-12 * max(design.chi2, 1e-300))
    statistic = np.where(testable, (d2 / np.maximum(dfn, 1))
                         / (np.maximum(rest, 1e-300) / np.maximum(dfd, 1)), 0.0)
    p_value = np.where(testable, f_sf(statistic, np.maximum(dfn, 1), np.maximum(dfd, 1)), 1.0)
    return DeletionStatistics(d2=d2, dfn=dfn, p_value=p_value)


def deletion_statistics(result: FitResult, design: _Design | None = None
                        ) -> DeletionStatistics:
    """Leave-one-out statistics of every sample of a fit (see the module doc); design: the
    fit's ``_design`` if already computed."""
    n_samples = result.problem.measured.shape[0]
    design = design or _design(result)
    if design is None:
        return DeletionStatistics(np.zeros(n_samples), np.zeros(n_samples, dtype=int),
                                  np.ones(n_samples))
    return _left_out(design, np.arange(n_samples)[:, None])


def repeated_poses(problem: Problem) -> np.ndarray:
    """(N,) the pose of each sample (``pose_groups``) where that pose repeats a measurement
    (``repeats.repeat_pairs``: the same pose and marker more than once, a copied row
    included), -1 elsewhere: the poses tested as one."""
    poses = pose_groups(problem.dataset.samples)
    pairs = repeat_pairs(problem)
    return np.where(np.isin(poses, poses[pairs.ravel()]), poses, -1)


def n_repeated_poses(problem: Problem, poses: np.ndarray | None = None) -> int:
    """How many poses are tested as one (``repeated_poses``, or ``poses`` if given: its
    result), each one test of the family."""
    poses = repeated_poses(problem) if poses is None else poses
    return int(np.unique(poses[poses >= 0]).size)


@dataclass(frozen=True)
class _Worst:
    """The most significant pose tested as one: its samples (indices into the fit's own
    samples, ascending), each one's whitened leave-pose-out residual norm, the pose's
    p-value."""

    samples: np.ndarray
    sigmas: np.ndarray
    p_value: float


def _pose_residuals(design: _Design, members: np.ndarray) -> np.ndarray:
    """(s,) the whitened norm of each sample's residual had the fit not seen any sample of
    ``members`` (its pose): e = (I - H_gg)^-1 r_g, per sample."""
    m = design.whitened.shape[1]
    Q = design.Q[members].reshape(members.size * m, -1)
    h, V = np.linalg.eigh(Q @ Q.T)
    keep = (1.0 - h) > LEVERAGE_TOLERANCE
    projected = V.T @ design.whitened[members].ravel()
    e = V @ np.where(keep, projected / np.where(keep, 1.0 - h, 1.0), 0.0)
    return np.linalg.norm(e.reshape(members.size, m), axis=1)


def _worst_pose(design: _Design, poses: np.ndarray, identity: np.ndarray) -> _Worst | None:
    """The pose of more than one sample (``poses``: the pose of each of the fit's samples,
    -1 for one not tested as a pose; ``identity``: what each measures,
    ``repeats.measured_identity``) whose leave-one-pose-out test is the most significant;
    None without such poses."""
    tested = np.flatnonzero(poses >= 0)
    order = tested[np.argsort(poses[tested], kind="stable")]
    bounds = np.flatnonzero(np.diff(poses[order])) + 1
    by_size: dict[int, list[np.ndarray]] = {}
    for members in np.split(order, bounds):
        if members.size > 1:
            by_size.setdefault(members.size, []).append(np.sort(members))
    best: tuple[float, np.ndarray] | None = None
    for groups in by_size.values():  # one stacked test per pose size
        members = np.stack(groups)
        reads = np.array([g.size / np.unique(identity[g]).size for g in groups])
        p_value = _left_out(design, members, reads).p_value
        k = int(np.argmin(p_value))
        if best is None or p_value[k] < best[0]:
            best = (float(p_value[k]), members[k])
    if best is None:
        return None
    return _Worst(best[1], _pose_residuals(design, best[1]), best[0])


def find_outliers(result: FitResult, alpha: float,
                  refit: Callable[[FitResult, np.ndarray], FitResult]
                  ) -> tuple[tuple[Outlier, ...], FitResult]:
    """The outliers of a fit, most significant first (every sample of a pose read more than
    once named as one outlier: ``test`` "pose"), and the fit without them.

    refit(fit, keep): the fit's model refitted on the samples ``keep`` (indices into the
    fit's own samples). Returns the input fit unchanged when no sample is an outlier.
    """
    n_samples = result.problem.measured.shape[0]
    poses = repeated_poses(result.problem)
    n_poses = n_repeated_poses(result.problem, poses)
    identity = measured_identity(result.problem)
    threshold = alpha / max(n_samples + n_poses, 1)
    limit = max(1, int(MAX_OUTLIER_FRACTION * n_samples))
    kept = np.arange(n_samples)  # dataset indices of the current fit's samples
    current = result
    found: list[Outlier] = []
    # repeats first: a pair that disagrees names its worse-fitted sample
    repeats = check_repeats(result.problem, alpha)
    if repeats.pairs.size:
        d2 = deletion_statistics(result).d2
        bad = np.flatnonzero(repeats.disagreeing)
        for k in bad[np.argsort(repeats.p_value[bad])][:limit]:
            pair = repeats.pairs[k]
            sample = int(pair[np.argmax(d2[pair])])
            if all(o.sample != sample for o in found):
                found.append(Outlier(sample, float(np.sqrt(repeats.statistic[k])),
                                     float(repeats.p_value[k]), test="repeat"))
        if found:
            keep_local = np.setdiff1d(kept, [o.sample for o in found])
            current = refit(current, keep_local)
            kept = kept[keep_local]
    while len(found) < limit:
        design = _design(current)
        stats = deletion_statistics(current, design)
        worst = int(np.argmin(stats.p_value))
        pose = (_worst_pose(design, poses[kept], identity[kept])
                if n_poses and design is not None else None)
        if pose is not None and pose.p_value < stats.p_value[worst] \
                and len(found) + pose.samples.size <= limit:
            if not pose.p_value < threshold:
                break
            found += [Outlier(sample=int(kept[i]), sigma=float(sigma), p_value=pose.p_value,
                              test="pose")
                      for i, sigma in zip(pose.samples, pose.sigmas, strict=True)]
            keep_local = np.setdiff1d(np.arange(kept.size), pose.samples)
        else:
            p_value = float(stats.p_value[worst])
            if not p_value < threshold:
                break
            found.append(Outlier(sample=int(kept[worst]),
                                 sigma=float(np.sqrt(stats.d2[worst])), p_value=p_value))
            keep_local = np.delete(np.arange(kept.size), worst)
        current = refit(current, keep_local)
        kept = kept[keep_local]
    return tuple(found), current
