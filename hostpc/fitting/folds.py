"""Cross-validation folds grouped the way the data was taken: by pose.

A held-out figure is honest only if a held-out sample has no twin left in training. The
samples of one pose (several markers seen at once, a pose measured twice, the repeated
contacts of one probe pose) share the robot's joint state, so whatever error the joints
carry at that pose is common to them: put one in training and the others held out, and the
fit has already seen the error it is asked to predict. Every held-out figure therefore
assigns whole poses to folds:

- ``pose_groups``: samples whose joint state (``q``, ``q_head``, the observed arm of a
  dual-loop sample) agrees within ``POSE_TOLERANCE_RAD`` in every joint belong to one pose
  (transitively: a chain of near-equal samples is one pose). Distinct poses of a plan differ
  by degrees; encoder read-backs of one commanded pose by far less than the tolerance. A
  sample that holds only part of the robot's state (dual_loop: the observed arm's joints)
  also shares its pose with the other samples of its capture (``capture_keys``: the same
  head state ``q_head`` at the same time ``t``): dual_loop's two arms seen at one pose.
- ``fold_indices``: the poses, ordered by their smallest joint vector (so the order of the
  rows in the file does not matter), are dealt to the folds by a seeded permutation, one
  pose at a time: the folds hold equal numbers of poses (+-1), and every model compared on
  one dataset sees the same folds.

Pure numpy (the CLI imports no scipy): the grouping sorts the rows along one fixed random
direction and compares only neighbours within the tolerance window, O(N log N).
"""

from __future__ import annotations

import numpy as np

from hostpc.dataset import Samples

POSE_TOLERANCE_RAD = 1e-3
"""Two samples are of one pose if every joint agrees within this (rad; 0.057 deg, m for a
prismatic joint): far below the spacing of planned poses (degrees), far above the read-back
of one commanded pose (encoder noise, servo error: a pose measured twice and read back with
5e-5 rad of noise per joint split into two poses at the former 1e-4, and its held-out
figure came out 4-6 % optimistic, review of the ninth stop). The poses of the public data
sets and the examples group alike at 1e-4, 1e-3 and 3e-3."""

FOLD_SEED = 20261126
"""Seed of the permutation that deals poses to folds (fixed: the same folds on every run)."""

_NAN_STANDIN = 1.0e6
"""Stand-in for an absent joint (a dual-loop arm padded with NaN): equal to itself."""


def pose_keys(samples: Samples) -> np.ndarray:
    """(N, k) the joint state of each sample: q, then q_head, then the observed arm's code
    (dual_loop), NaN (absent) replaced by a stand-in so that absent equals absent."""
    columns = [np.asarray(samples.q, float)]
    if samples.q_head is not None:
        columns.append(np.asarray(samples.q_head, float))
    if samples.chain is not None:
        # the arm's code: arms differ by 1, far beyond the tolerance
        _, codes = np.unique(np.asarray(samples.chain), return_inverse=True)
        columns.append(codes.reshape(-1, 1).astype(float))
    keys = np.concatenate(columns, axis=1) if len(columns) > 1 else columns[0]
    return np.where(np.isfinite(keys), keys, _NAN_STANDIN)


def capture_keys(samples: Samples) -> tuple[np.ndarray, np.ndarray] | None:
    """Rows (K,) and their keys (K, k) of the samples that hold only part of the robot's
    joint state, one robot state being one capture: dual_loop's observed arm, whose capture
    is its head state ``q_head`` and time ``t`` (both arms' targets seen in one capture
    share both; another pose differs in ``t`` by a move). None: each sample holds the whole
    state (no ``chain``); a sample without ``t`` joins no capture. `pose_groups` uses the
    keys only where no key holds one chain twice (else they name no capture: a fixed head
    and one ``t`` for every sample)."""
    if samples.chain is None or samples.q_head is None:
        return None
    t = np.asarray(samples.t, float).reshape(-1, 1)
    keys = np.concatenate([np.asarray(samples.q_head, float), t], axis=1)
    rows = np.flatnonzero(np.all(np.isfinite(keys), axis=1))
    return rows, keys[rows]


def _close_pairs(keys: np.ndarray, tolerance: float) -> tuple[np.ndarray, np.ndarray]:
    """Index pairs (a, b) of the rows of keys (N, k) that agree within tolerance in every
    column (each pair once): the rows sorted along one fixed random direction, only
    neighbours within the tolerance window compared."""
    n = keys.shape[0]
    direction = np.random.default_rng(FOLD_SEED).standard_normal(keys.shape[1])
    direction /= np.sum(np.abs(direction))  # |projection difference| <= max-abs difference
    projection = keys @ direction
    order = np.argsort(projection, kind="stable")
    sorted_projection = projection[order]
    first: list[np.ndarray] = []
    second: list[np.ndarray] = []
    candidates = np.arange(n - 1)
    step = 1
    while candidates.size:
        close = sorted_projection[candidates + step] - sorted_projection[candidates] <= tolerance
        candidates = candidates[close]
        if not candidates.size:
            break
        a, b = order[candidates], order[candidates + step]
        same = np.max(np.abs(keys[a] - keys[b]), axis=1) <= tolerance
        first.append(a[same])
        second.append(b[same])
        candidates = candidates[candidates + step + 1 < n]
        step += 1
    if not first:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    return np.concatenate(first), np.concatenate(second)


def pose_groups(samples: Samples, tolerance: float = POSE_TOLERANCE_RAD) -> np.ndarray:
    """(N,) int: the pose of each sample, numbered 0.. in the order of each pose's smallest
    joint vector (lexicographic), so the numbering does not depend on the row order."""
    keys = pose_keys(samples)
    n = keys.shape[0]
    if n == 0:
        return np.zeros(0, dtype=np.int64)
    left, right = _close_pairs(keys, tolerance)
    captures = capture_keys(samples)
    if captures is not None and captures[0].size:
        rows, capture = captures
        a, b = _close_pairs(capture, tolerance)
        chain = np.asarray(samples.chain)
        if not np.any(chain[rows[a]] == chain[rows[b]]):
            # a capture sees each chain once; where one key holds a chain twice (a file
            # with a fixed head and the same t everywhere) the key names no capture
            left, right = np.concatenate([left, rows[a]]), np.concatenate([right, rows[b]])
    label = np.arange(n)
    if left.size:
        while True:  # connected components by label propagation (edges are few)
            low = np.minimum(label[left], label[right])
            before = label.copy()
            np.minimum.at(label, left, low)
            np.minimum.at(label, right, low)
            label = label[label]
            if np.array_equal(label, before):
                break
    # number the poses by their lexicographically smallest joint vector
    lexical = np.lexsort(keys.T[::-1])
    _, first_seen = np.unique(label[lexical], return_index=True)
    representatives = label[lexical][np.sort(first_seen)]
    number = np.empty(n, dtype=np.int64)
    number[representatives] = np.arange(representatives.size)
    return number[label]


def fold_indices(samples: Samples, folds: int, seed: int = FOLD_SEED
                 ) -> list[np.ndarray] | None:
    """Sample indices of each of `folds` folds, whole poses dealt by a seeded permutation
    (see the module docstring); None with fewer than two poses per fold (or folds < 2)."""
    groups = pose_groups(samples)
    count = int(groups.max()) + 1 if groups.size else 0
    if folds < 2 or count < 2 * folds:
        return None
    fold_of_pose = np.random.default_rng(seed).permutation(count) % folds
    assignment = fold_of_pose[groups]
    return [np.flatnonzero(assignment == k) for k in range(folds)]


def repeated_samples(samples: Samples, measured: np.ndarray) -> tuple[tuple[int, int], ...]:
    """(repeat, first) index pairs of samples that repeat an earlier sample EXACTLY: the
    same joint state and the same measured values (N, m), to the bit. A real second
    measurement of a pose differs by its noise; an exact repeat is a copied row, which a
    fit would count as new data (its dof, chi2 and sigmas as if measured twice)."""
    keys = pose_keys(samples)
    return exact_repeats(np.concatenate(
        [keys, np.asarray(measured, float).reshape(keys.shape[0], -1)], axis=1))


def exact_repeats(rows: np.ndarray) -> tuple[tuple[int, int], ...]:
    """(repeat, first) index pairs of the rows of ``rows`` (N, k) equal to an earlier row in
    every value (also `hostpc import`'s check of a CSV's rows)."""
    if rows.shape[0] < 2:
        return ()
    _, first, inverse = np.unique(rows, axis=0, return_index=True, return_inverse=True)
    owner = first[np.ravel(inverse)]
    return tuple((int(i), int(owner[i])) for i in range(rows.shape[0]) if owner[i] != i)
