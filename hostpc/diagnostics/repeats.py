"""Repeated measurements as the direct test of measurement consistency.

A pose measured twice (the same joints, the same marker) must give the same measurement up
to the noise: a pair that disagrees beyond it is a glitch (a bumped nest, a beam break, a
mis-latched contact), whatever the model says. A pair that agrees shows only that the
instrument repeated its reading: a pose read wrong the same way twice (a bumped target, a
wrong joint reading, a copied row) agrees with itself, so whether the pose is good is the
leave-one-pose-out test's question (``outliers``), never settled here.

For a pair (i, j) with measurements y_i, y_j (m,) and stated covariances C_i, C_j, the
difference d = y_i - y_j is zero-mean with covariance C_i + C_j if both are good, so
``d^T (C_i + C_j)^-1 d`` is chi-square with m degrees of freedom. A pair disagrees when its
p-value is below ``alpha / K`` (Bonferroni over the K pairs). Pairs are taken within each
repeat group (``pose_groups`` and the sample's marker / observed arm): every pair of a
group of a few, consecutive pairs of a larger one (linear in the group's size).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hostpc.diagnostics.distributions import chi2_sf
from hostpc.fitting.folds import pose_groups
from hostpc.model.layout import Problem

ALL_PAIRS_UP_TO = 6
"""A repeat group of at most this many samples is tested pair by pair; a larger one by
consecutive pairs only."""


@dataclass(frozen=True, eq=False)  # holds arrays: compared by identity (__init__.py)
class RepeatCheck:
    """pairs: (K, 2) sample indices measured at one pose with one identity; statistic:
    (K,) chi-square of each pair's difference with ``dof`` degrees of freedom; p_value:
    (K,); threshold: the Bonferroni-corrected level (alpha / K)."""

    pairs: np.ndarray
    statistic: np.ndarray
    p_value: np.ndarray
    dof: int
    threshold: float

    @property
    def disagreeing(self) -> np.ndarray:
        """(K,) bool: pairs that disagree beyond the noise."""
        return self.p_value < self.threshold


def measured_identity(problem: Problem) -> np.ndarray:
    """(N,) int: what each sample measures at its pose (a marker for world_point, an arm for
    dual_loop; 0 when a pose measures one thing), so that two samples of one pose with the
    same identity repeat one measurement."""
    samples = problem.dataset.samples
    measured = samples.fields.get("marker", samples.chain)
    if measured is None:
        return np.zeros(samples.n, dtype=np.int64)
    _, codes = np.unique(np.asarray(measured).astype(str), return_inverse=True)
    return np.ravel(codes).astype(np.int64)


def repeat_pairs(problem: Problem) -> np.ndarray:
    """(K, 2) pairs of samples that repeat one measurement (same pose, same marker)."""
    groups = pose_groups(problem.dataset.samples)
    identity = measured_identity(problem)
    key = groups * (int(identity.max(initial=0)) + 1) + identity
    order = np.argsort(key, kind="stable")
    bounds = np.flatnonzero(np.diff(key[order])) + 1
    pairs: list[tuple[int, int]] = []
    for members in np.split(order, bounds):
        if members.size < 2:
            continue
        if members.size <= ALL_PAIRS_UP_TO:
            pairs += [(int(a), int(b)) for k, a in enumerate(members) for b in members[k + 1:]]
        else:
            pairs += [(int(a), int(b)) for a, b in zip(members[:-1], members[1:], strict=True)]
    return np.array(pairs, dtype=np.int64).reshape(-1, 2)


def check_repeats(problem: Problem, alpha: float) -> RepeatCheck:
    """Test every repeat pair of the problem's samples (module docstring)."""
    pairs = repeat_pairs(problem)
    m = problem.measured.shape[1]
    if not pairs.size:
        empty = np.zeros(0)
        return RepeatCheck(pairs, empty, empty, m, alpha)
    first, second = pairs[:, 0], pairs[:, 1]
    difference = problem.measured[first] - problem.measured[second]
    W = problem.sqrt_information
    covariance = (np.linalg.inv(np.einsum("nki,nkj->nij", W[first], W[first]))
                  + np.linalg.inv(np.einsum("nki,nkj->nij", W[second], W[second])))
    ok = np.all(np.isfinite(difference), axis=1)
    statistic = np.zeros(len(pairs))
    statistic[ok] = np.einsum("ni,ni->n", difference[ok],
                              np.linalg.solve(covariance[ok], difference[ok][:, :, None])[:, :, 0])
    p_value = np.array([chi2_sf(float(s), m) if good else 1.0
                        for s, good in zip(statistic, ok, strict=True)])
    return RepeatCheck(pairs, statistic, p_value, m, alpha / len(pairs))
