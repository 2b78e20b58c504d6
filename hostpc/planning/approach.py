"""Approach directions: reach every joint from both sides when the model has an effect that
depends on them (pure; nominal model).

A backlash-like effect shifts a joint by +b or -b depending on the direction the joint last
moved (``approach``). If a joint always arrives the same way - on sphere_probe, joint 4 of
a UR moves the same way in every guarded move toward the sphere - its shift is a constant
and no data can tell it from the joint's zero offset: the fit holds one of them. The fix is
in the plan: arrive from the other side on about half of the samples.

- ``approach_dependent_effects(spec)``: the effects of a model spec that declare
  ``approach_dependent`` (``hostpc.model.effect.Effect``); the planners change nothing
  when there are none (no robot time added).
- ``travel_signs``, ``unbalanced_joints``: the recorded approach of moves, and the joints
  whose rarer direction falls below ``MIN_SHARE``.
- ``balance_guarded_moves``: for guarded moves (q_start -> q_target), a new target for
  about half of the moves of each unbalanced joint, with the same tip end point but that
  joint travelling the other way (the other joints make up the tip position; the tool
  turns a little on the way, which a touch probe's ball does not mind). The number of
  moves and their start poses stay the same.
- (sphere_probe's plan balanced with these: ``hostpc.kinds.sphere_probe.planning.contacts``.)
- ``ApproachTally``, ``via_point``, ``approach_after``: for free moves to poses in tour
  order (stereo_target, world_point; the moves themselves: hostpc.methods.approach_moves):
  the directions recorded so far; once a joint has arrived one way on fewer than
  ``MIN_SHARE`` of the samples (after ``WARMUP_SAMPLES``, and unlikely by chance:
  ``ONE_SIDED_P``), its moves that would arrive the common way go through a via-point
  ``VIA_STEP`` past the pose until it is half and half. A tour balanced by itself gets no
  via-point.

Units: rad, m; q arrays (N, n) as in docs/conventions.md.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hostpc.kinematics import Chain, forward, point_jacobian, screws
from hostpc.model.registry import available_effects

MIN_SHARE = 0.3
"""A joint whose rarer approach direction is below this share of the moves is balanced."""
REVERSAL_FRACTION = 0.25
"""A reversed joint travels this fraction of its natural travel the other way..."""
MIN_REVERSAL = 2e-3
"""... and at least this much (rad): more than any backlash it must take up."""
MAX_PATH_CHANGE = 1e-3
"""m: the tip's path at mid-move may move this far from the planned move's (a joint-space
line curves in space; reversing a joint that others must make up for curves it more)."""
WARMUP_SAMPLES = 8
"""Free moves: a joint is judged one-sided only after this many samples..."""
ONE_SIDED_P = 0.01
"""... and when so few arrivals from its rarer side are this improbable for a tour that
comes from either side at random (two-sided binomial p-value)."""
VIA_STEP = 0.05
"""rad: how far past a pose a via-point takes a joint that should arrive the other way."""
MAX_TURN = 0.1
"""rad: the tool may end this much turned from the planned target (the stylus meets the
sphere at a slightly different angle; a ball stylus does not mind a few degrees)."""
NEWTON_STEPS = 6
TIP_TOLERANCE = 1e-7  # m


def approach_dependent_effects(spec: str | Iterable[str] | None,
                               plugins: Iterable[str | Path] = ()) -> list[str]:
    """The effects named in a model spec (``"+backlash"``, ``"joint_offsets,backlash"``;
    None: the default model) that depend on approach directions. Names the registry does
    not know are left to the fit to report."""
    if spec is None:
        return []
    items = [s.strip() for s in spec.split(",")] if isinstance(spec, str) else list(spec)
    registry = available_effects(tuple(plugins))
    names = [item.lstrip("+") for item in items if item and not item.startswith("-")]
    return [name for name in names
            if name in registry and getattr(registry[name], "approach_dependent", False)]


def travel_signs(q_from: np.ndarray, q_to: np.ndarray) -> np.ndarray:
    """(N, n) approach of each joint after moving q_from -> q_to (N, n): the sign of the
    travel, +1 where a joint does not move (as the acquisition records it)."""
    signs = np.sign(np.asarray(q_to, float) - np.asarray(q_from, float))
    signs[signs == 0] = 1.0
    return signs


def unbalanced_joints(signs: np.ndarray, min_share: float = MIN_SHARE) -> np.ndarray:
    """(n,) True for the joints whose rarer approach direction has less than ``min_share``
    of the samples signs (N, n)."""
    if signs.shape[0] == 0:
        return np.zeros(signs.shape[1], dtype=bool)
    positive = np.mean(signs > 0, axis=0)
    return np.asarray(np.minimum(positive, 1.0 - positive) < min_share)


def _tip(chain: Chain, q: np.ndarray, tip: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Tip position (3,) (base, m) and its joint Jacobian (3, n) at q (n,)."""
    poses = forward(chain, q[None, :])
    T = poses.T_base_flange[0]
    x = T[:3, :3] @ tip + T[:3, 3]
    J = point_jacobian(screws(chain, poses), x[None, :])[0, :, : chain.n]
    return x, J


def reversed_target(chain: Chain, q_start: np.ndarray, q_target: np.ndarray, tip: np.ndarray,
                    joints: Sequence[int], q_min: np.ndarray | None = None,
                    q_max: np.ndarray | None = None) -> np.ndarray | None:
    """A guarded-move target (n,) with the same tip end point (nominal) as q_target, from
    which the ``joints`` (0-based) travel the other way from q_start: each by
    ``max(REVERSAL_FRACTION |natural travel|, MIN_REVERSAL)``; the other joints change by
    the least (minimum norm) that puts the tip back. None when that fails, leaves the
    joint limits, turns the tool more than ``MAX_TURN`` or moves the tip's mid-move path
    more than ``MAX_PATH_CHANGE``."""
    q_start = np.asarray(q_start, float)
    q_target = np.asarray(q_target, float)
    travel = q_target - q_start
    flipped = np.zeros(chain.n, dtype=bool)
    flipped[list(joints)] = True
    natural = np.where(travel[flipped] == 0.0, 1.0, np.sign(travel[flipped]))
    q = q_target.copy()
    q[flipped] = q_start[flipped] - natural * np.maximum(
        REVERSAL_FRACTION * np.abs(travel[flipped]), MIN_REVERSAL)
    goal, _ = _tip(chain, q_target, tip)
    free = ~flipped
    for _ in range(NEWTON_STEPS):
        x, J = _tip(chain, q, tip)
        error = goal - x
        if np.linalg.norm(error) < TIP_TOLERANCE:
            break
        q[free] += np.linalg.lstsq(J[:, free], error, rcond=None)[0]
    else:
        if np.linalg.norm(goal - _tip(chain, q, tip)[0]) > 1e3 * TIP_TOLERANCE:
            return None
    low = chain.q_min if q_min is None else q_min
    high = chain.q_max if q_max is None else q_max
    if np.any(q < low) or np.any(q > high):
        return None
    if np.any(travel_signs(q_start, q)[flipped] == natural):
        return None
    R_planned, R_new = forward(chain, np.stack([q_target, q])).T_base_flange[:, :3, :3]
    cos_turn = (np.trace(R_planned.T @ R_new) - 1.0) / 2.0
    if cos_turn < np.cos(MAX_TURN):
        return None
    planned_middle, _ = _tip(chain, 0.5 * (q_start + q_target), tip)
    middle, _ = _tip(chain, 0.5 * (q_start + q), tip)
    if np.linalg.norm(middle - planned_middle) > MAX_PATH_CHANGE:
        return None
    return q


def balance_guarded_moves(chain: Chain, q_start: np.ndarray, q_target: np.ndarray,
                          tip: np.ndarray, joints: Sequence[int] | None = None,
                          q_min: np.ndarray | None = None, q_max: np.ndarray | None = None,
                          min_share: float = MIN_SHARE) -> np.ndarray:
    """New guarded-move targets (N, n) so that every joint of ``joints`` (0-based; None:
    all) arrives from both sides: for each unbalanced joint, every other move of its
    common direction (a different alternation per joint, so two balanced joints do not
    always flip together) gets a ``reversed_target`` (where two joints cannot reverse
    together, one alone); a move whose reversal fails keeps its target.
    q_start, q_target: (N, n) rad; tip: (3,) tool point in the flange (m)."""
    q_start = np.asarray(q_start, float)
    targets = np.array(q_target, dtype=float, copy=True)
    signs = travel_signs(q_start, targets)
    candidates = np.zeros(chain.n, dtype=bool)
    candidates[list(range(chain.n) if joints is None else joints)] = True
    unbalanced = np.flatnonzero(unbalanced_joints(signs, min_share) & candidates)
    flip = np.zeros(targets.shape, dtype=bool)
    for order, j in enumerate(unbalanced):
        common = 1.0 if np.mean(signs[:, j] > 0) >= 0.5 else -1.0
        rows = np.flatnonzero(signs[:, j] == common)
        flip[rows[(np.arange(rows.size) // 2**order) % 2 == 0], j] = True
    for i in np.flatnonzero(flip.any(axis=1)):
        wanted = np.flatnonzero(flip[i]).tolist()
        # all the joints this move should reverse, else the first that can be alone
        for joint_set in [wanted, *([j] for j in wanted)] if len(wanted) > 1 else [wanted]:
            reversed_q = reversed_target(chain, q_start[i], targets[i], tip, joint_set,
                                         q_min, q_max)
            if reversed_q is not None:
                targets[i] = reversed_q
                break
    return targets


def one_sided_p(rare: int, total: int) -> float:
    """Two-sided binomial p-value of ``rare`` or fewer arrivals from one side in ``total``
    samples, if either side were equally likely."""
    tail = sum(math.comb(total, k) for k in range(rare + 1)) / 2.0**total
    return min(1.0, 2.0 * tail)


@dataclass(frozen=True)
class ApproachTally:
    """The approach directions recorded so far in a run of free moves: positive (n,) how
    many samples each joint reached moving in +, total the samples, flagged (n,) the joints
    found one-sided (they are then balanced toward half and half)."""

    positive: np.ndarray
    total: int
    flagged: np.ndarray

    @classmethod
    def empty(cls, n_joints: int) -> ApproachTally:
        return cls(np.zeros(n_joints), 0, np.zeros(n_joints, dtype=bool))

    def add(self, signs: np.ndarray, min_share: float = MIN_SHARE,
            warmup: int = WARMUP_SAMPLES) -> ApproachTally:
        """The tally with one more sample's recorded approach signs (n,)."""
        positive = self.positive + (np.asarray(signs) > 0)
        total = self.total + 1
        flagged = self.flagged.copy()
        if total >= warmup:
            share = positive / total
            rare = np.minimum(positive, total - positive)
            flagged |= (np.minimum(share, 1.0 - share) < min_share) & np.array(
                [one_sided_p(int(k), total) < ONE_SIDED_P for k in rare])
        return ApproachTally(positive, total, flagged)


def via_point(tally: ApproachTally, q_from: np.ndarray | None, q: np.ndarray,
              joints: np.ndarray | None = None, step: float = VIA_STEP,
              q_min: np.ndarray | None = None, q_max: np.ndarray | None = None
              ) -> np.ndarray | None:
    """A via-point (n,) for the free move q_from -> q (n,), or None to move directly: the
    joints the tally flagged (of ``joints``, a (n,) mask; None: all) whose direct move
    would arrive the way they arrived more often so far go ``step`` rad past q first, so
    they arrive the other way; the other joints move straight to q on the first leg.
    A via-point outside [q_min, q_max] is dropped for that joint."""
    if q_from is None or tally.total == 0:
        return None
    signs = travel_signs(np.asarray(q_from, float)[None], np.asarray(q, float)[None])[0]
    majority = np.where(tally.positive * 2 >= tally.total, 1.0, -1.0)
    reverse = tally.flagged & (signs == majority)
    if joints is not None:
        reverse &= joints
    via = np.array(q, dtype=float, copy=True)
    via[reverse] += signs[reverse] * step
    if q_min is not None and q_max is not None:
        outside = (via < q_min) | (via > q_max)
        via[outside] = np.asarray(q, float)[outside]
        reverse &= ~outside
    return via if np.any(reverse) else None


def approach_after(q_from: np.ndarray | None, via: np.ndarray | None, q: np.ndarray
                   ) -> np.ndarray:
    """(n,) recorded approach signs of q reached from q_from through via (None: directly):
    a joint the second leg moves arrives the way that leg goes; one it does not move
    keeps the first leg's direction."""
    q = np.asarray(q, float)
    if q_from is None:
        return np.ones(q.size)
    if via is None:
        return travel_signs(np.asarray(q_from, float)[None], q[None])[0]
    first = travel_signs(np.asarray(q_from, float)[None], np.asarray(via, float)[None])[0]
    second = np.sign(q - via)
    return np.where(second != 0, second, first)

