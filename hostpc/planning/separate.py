"""Separating poses: the fewest extra poses after which two confounded candidates part.

Pure numerics. ``criterion(rows)`` gives the two noncentralities of a set of whitened
Jacobian rows (``hostpc.diagnostics.separation.noncentralities``: A given B, B given A);
the measured data give the starting rows. Greedy, like the D-optimal planner, over whole
groups of the pool (sphere_probe: an orientation's contacts; else single poses): each step
adds the group that most raises ``log min(lambda_A, needed_A) + log min(lambda_B, needed_B)``
(a D-criterion on the two contrasts, capped where a test has its power: past it a contrast
needs no more), ties going to the larger sum; it stops as soon as both reach ``needed``,
or when ``max_groups`` are taken, or when no group raises either.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

Noncentralities = Callable[[np.ndarray], tuple[float, float]]


@dataclass(frozen=True)
class SeparatingPlan:
    """indices: pool indices of the chosen poses, their groups in pool order (the kind's
    safe visiting order of its groups, like ``design.in_pool_order``);
    before / after: the two noncentralities with the measured data alone and with the
    chosen poses added; reached: both reach the needed noncentrality."""

    indices: np.ndarray
    before: tuple[float, float]
    after: tuple[float, float]
    reached: bool


def _score(values: tuple[float, float], needed: tuple[float, float]) -> tuple[float, float]:
    capped = [max(min(v, n), 1e-300) for v, n in zip(values, needed, strict=True)]
    return (math.log(capped[0]) + math.log(capped[1]), values[0] + values[1])


def _reached(values: tuple[float, float], needed: tuple[float, float]) -> bool:
    return values[0] >= needed[0] and values[1] >= needed[1]


def separating_poses(measured: np.ndarray, pool: np.ndarray,
                     members: Sequence[np.ndarray], criterion: Noncentralities,
                     needed: tuple[float, float], max_groups: int) -> SeparatingPlan:
    """The groups (``members``: index arrays into ``pool`` (N, m, P)) to add to the
    ``measured`` rows (R, P); see the module docstring."""
    flat = [pool[np.asarray(g, dtype=int)].reshape(-1, pool.shape[2]) for g in members]
    rows = measured
    before = criterion(rows)
    current = before
    chosen: list[int] = []
    while not _reached(current, needed) and len(chosen) < max_groups:
        best: tuple[tuple[float, float], int, tuple[float, float]] | None = None
        for g, block in enumerate(flat):
            if g in chosen or block.shape[0] == 0:
                continue
            values = criterion(np.vstack([rows, block]))
            score = _score(values, needed)
            if best is None or score > best[0]:
                best = (score, g, values)
        if best is None or best[0] <= _score(current, needed):
            break
        chosen.append(best[1])
        rows = np.vstack([rows, flat[best[1]]])
        current = best[2]
    indices = (np.concatenate([np.asarray(members[g], dtype=int) for g in sorted(chosen)])
               if chosen else np.zeros(0, dtype=int))
    return SeparatingPlan(indices, before, current, _reached(current, needed))
