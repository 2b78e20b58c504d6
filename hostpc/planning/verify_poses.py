"""Verification poses: how many, and which ones, so that the verification costs little
robot time and still detects a wrong calibration.

Pure numerics (no robot, no I/O).

How many (`verify_poses_for_power`): the verification is a chi-square test of K fresh
poses (`hostpc.calibrate.verify`, m measured coordinates each, n = K m dof) at a false-FAIL
rate alpha. A model error that leaves an expected whitened squared error `d2` per pose makes
T a non-central chi-square with non-centrality K d2; the power is
`P(ncx2(n, K d2) > chi2.isf(alpha, n))`. The count is the fewest K whose power reaches
`power` for the error size `d2` (docs/calibrate.md has the table).

Which ones (`nearby_verify_poses`): a seeded random draw of `sample_factor` x K candidates
among those the plan did not use, of which the K nearest (a nearest-neighbour walk from the
robot's pose after the fit poses, by the joint move time) are visited as a tour
(`hostpc.planning.tour`). The draw keeps the poses fresh (never a fit pose, not chosen by
their measurements). With sample_factor 1 (the default, SAMPLE_FACTOR) it is the plain
random choice, toured; a larger factor shortens the travel but clusters the poses, which
costs power against effects that vary over the workspace.

With a target sigma the plan (hostpc.calibrate.run_plan) chooses its verification poses
for their power against a missing joint compliance instead (`PowerDesign.choose`: the
most signal per second of move, settle and capture), and adds fit poses that let the
fit's own chi-square see it (`PowerDesign.check_poses`); the random choice above serves
the plans whose model has that effect and a grown plan's further verification poses
(chosen for power against the grown fit they caught the same 39 of 40 forced pushes,
docs/performance.md).

Shapes: pool (N, n) rad; q_from (n,) rad; joint_speed: the moves' `tour.JointRates` at the
run's speed (the trapezoidal law), (n,) rad/s, or None (equal speeds).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hostpc.diagnostics.distributions import chi2_isf, ncx2_sf
from hostpc.planning.tour import (
    Rates,
    move_times,
    nearest_equivalents,
    nearest_neighbour,
    plan_tour,
)

DETECTABLE_D2 = 10.0
"""The error size the default verification must detect: expected whitened squared error
per pose (e.g. 1.8 stated sigmas on each of 3 coordinates; the simulator's hidden joint
compliance leaves about 10-70 per pose)."""
DETECTABLE_POWER = 0.95
"""The chance of a FAIL the default verification pose count gives for that error."""
SAMPLE_FACTOR = 1
"""Random candidates drawn per verification pose, of which the nearest are visited. 1: a
plain random choice (toured): drawing 2 or 5 per pose shortened the travel by a third to a
half but clustered the poses, and the verification then missed the hidden compliance in
9 of 20 forced pushes (docs/performance.md)."""


def verify_power(n_poses: int, d2: float, alpha: float, m: int = 3) -> float:
    """Chance that K = n_poses verification poses FAIL a model error of d2 per pose."""
    n = int(n_poses) * int(m)
    if n < 1:
        return 0.0
    return ncx2_sf(chi2_isf(alpha, n), n, n_poses * d2)


def verify_poses_for_power(d2: float = DETECTABLE_D2, power: float = DETECTABLE_POWER,
                           alpha: float = 0.01, m: int = 3, most: int = 200) -> int:
    """The fewest verification poses (2 at least) whose chi-square test detects an error of
    d2 per pose with `power` at false-FAIL rate alpha (module docstring); `most` if none."""
    for n_poses in range(2, most + 1):
        if verify_power(n_poses, d2, alpha, m) >= power:
            return n_poses
    return most


def nearby_verify_poses(pool: np.ndarray, unused: np.ndarray, q_from: np.ndarray,
                        n_verify: int, rng: np.random.Generator,
                        sample_factor: int = SAMPLE_FACTOR,
                        joint_speed: Rates = None) -> np.ndarray:
    """Indices into pool (N, n) of n_verify verification poses among `unused` (indices),
    in visiting order from q_from (module docstring)."""
    unused = np.asarray(unused, dtype=int)
    n_verify = min(int(n_verify), unused.size)
    if n_verify < 1:
        return np.zeros(0, dtype=int)
    drawn = rng.choice(unused, size=min(unused.size, max(1, sample_factor) * n_verify),
                       replace=False)
    nearest = drawn[nearest_neighbour(pool[drawn], q_from, joint_speed)[:n_verify]]
    return nearest[plan_tour(pool[nearest], q_from, joint_speed)]


POWER_EFFECTS = ("joint_compliance",)
"""The effects a short plan's verification poses are chosen to catch when the model lacks
them (`PowerDesign`): a joint bending under its gravity load varies over the workspace, so
a short fit absorbs it into its offsets where it measured, and the verification must look
where that no longer holds."""


@dataclass(frozen=True)
class PowerDesign:
    """Where a verification (or a fit's own chi-square) sees effects the model lacks, from
    the designs before anything moves. A: (N, m, P) the model's whitened Jacobian at the
    pool's poses; B: (N, m, Q) the missing effects' (POWER_EFFECTS), all parameters scaled
    by ONE factor (`scaled`: the parameter the pool sees most leaves a whitened squared
    error of 1 per pose in RMS), so a joint the gravity hardly loads counts as little as it
    bends (scaling each parameter alone made a wrist's compliance count as much as the
    shoulder's, and the chosen poses missed the hidden compliance: docs/performance.md).
    Only the ranking of poses is used, never the scale.

    A fit of the poses F moves the model by K = A_F^+ B_F per unit of each missing
    parameter, so a verification pose v keeps the error r = (B_v - A_v K) e_j, and the test
    (hostpc.calibrate.verify) weighs it with the noise plus the fit's prediction
    uncertainty, S_v = I + A_v (A_F^T A_F)^+ A_v^T (whitened): a pose far from a compact fit
    extrapolates, and its uncertain prediction hides the error. The pose's signal is the
    mean over j of r^T S_v^-1 r."""

    A: np.ndarray
    B: np.ndarray

    @classmethod
    def scaled(cls, A: np.ndarray, B: np.ndarray) -> PowerDesign:
        """B's parameters scaled by one factor, those the pool cannot see dropped (class
        docstring)."""
        size = np.mean(np.sum(B**2, axis=1), axis=0)
        largest = max(float(np.max(size, initial=0.0)), 1e-300)
        seen = size > 1e-12 * largest
        return cls(A, B[:, :, seen] / np.sqrt(largest))

    def signal(self, fit: np.ndarray) -> np.ndarray:
        """(N,) each pool pose's signal after a fit of the pool poses `fit` (indices); 0
        at the fit poses."""
        fit = np.asarray(fit, dtype=int)
        P, Q = self.A.shape[2], self.B.shape[2]
        A_fit = self.A[fit].reshape(-1, P)
        K = np.linalg.lstsq(A_fit, self.B[fit].reshape(-1, Q), rcond=None)[0]
        R = self.B - self.A @ K
        G = np.linalg.pinv(A_fit.T @ A_fit)
        S = np.eye(self.A.shape[1]) + (self.A @ G) @ np.swapaxes(self.A, 1, 2)
        out = np.einsum("nmq,nmq->n", R, np.linalg.solve(S, R)) / max(Q, 1)
        out[fit] = 0.0
        return np.asarray(out)

    def choose(self, fit: np.ndarray, unused: np.ndarray, n_verify: int, q: np.ndarray,
               q_from: np.ndarray, joint_speed: Rates, per_pose_s: float,
               limits: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
        """Pool indices of n_verify verification poses among `unused`, in the order
        chosen: from q_from (n,) each step takes the pose with the most signal per second
        of its move (q (N, n) the pool, joint_speed the joints' rates at the run's speed,
        `tour.move_times`; a full-turn joint to its equivalent nearest within `limits`
        (q_min, q_max), `tour.nearest_equivalents`: no move that unwinds looks short),
        settle and capture (per_pose_s)."""
        unused = np.asarray(unused, dtype=int)
        signal = self.signal(fit)
        chosen: list[int] = []
        current = np.asarray(q_from, float)
        for _ in range(min(int(n_verify), unused.size)):
            reached = nearest_equivalents(current, q[unused], *limits)
            cost = move_times(current, reached, joint_speed) + per_pose_s
            score = signal[unused] / cost
            score[np.isin(unused, chosen)] = -np.inf
            best = int(np.argmax(score))
            k = int(unused[best])
            chosen.append(k)
            current = reached[best]
        return np.asarray(chosen, dtype=int)

    def check_poses(self, fit: np.ndarray, unused: np.ndarray, n_check: int, q: np.ndarray,
                    joint_speed: Rates, per_pose_s: float) -> np.ndarray:
        """Pool indices (among `unused`) of n_check further FIT poses that let the fit's
        own chi-square see a missing effect: adding pose v to the fit raises the
        chi-square's non-centrality by exactly v's signal (the innovation r^T S_v^-1 r of
        the class docstring), so each step takes the pose with the most signal per second
        of its detour (its move from the nearest pose of the fit so far, q (N, n) the pool,
        joint_speed the joints' rates at the run's speed) with its settle and capture."""
        measured = [int(k) for k in np.asarray(fit, dtype=int)]
        unused = np.asarray(unused, dtype=int)
        added: list[int] = []
        for _ in range(min(int(n_check), unused.size)):
            signal = self.signal(np.asarray(measured + added, dtype=int))
            detour = np.min(move_times(q[unused][:, None, :],
                                       q[measured + added][None, :, :], joint_speed), axis=1)
            score = signal[unused] / (detour + per_pose_s)
            score[np.isin(unused, added)] = -np.inf
            added.append(int(unused[int(np.argmax(score))]))
        return np.asarray(added, dtype=int)
