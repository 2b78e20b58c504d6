"""Free moves that bring every joint in from both sides when the model has an
approach-dependent effect (backlash): the I/O half of ``hostpc.planning.approach``.

A method that moves freely between poses (stereo_target, world_point) keeps one
``ApproachMoves`` per run: ``move`` goes to the pose, through a via-point when the tally
says a joint should arrive the other way (``planning.approach.via_point``), and ``signs``
gives the sample's recorded approach and counts it. Without such an effect in the model
(``settings.effects``), ``move`` is ``move_or_skip`` and ``signs`` is ``approach_signs``:
nothing changes and no robot time is added.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from hostpc.kinematics import Chain
from hostpc.methods.base import Phase, SampleRecord, approach_signs, move_or_skip
from hostpc.planning.approach import (
    ApproachTally,
    approach_after,
    approach_dependent_effects,
    via_point,
)
from hostpc.robots.base import MoveOutcome, RobotAdapter


class ApproachMoves:
    """The approach bookkeeping of one run's free moves (see the module docstring).

    settings: the run's settings (``effects``, ``plugins``, ``speed``); chain: the robot,
    whose joint limits bound the via-points (and the controller's, once ``bound`` is told
    them: the methods do when they plan)."""

    def __init__(self, settings: Any, chain: Chain) -> None:
        self.speed = float(settings.speed)
        self.chain = chain
        dependent = approach_dependent_effects(settings.effects, settings.plugins)
        self.tally = ApproachTally.empty(chain.n) if dependent else None
        self.vias = 0
        self._via: np.ndarray | None = None
        self.q_min = np.asarray(chain.q_min, dtype=float)
        self.q_max = np.asarray(chain.q_max, dtype=float)

    def bound(self, q_min: np.ndarray, q_max: np.ndarray) -> None:
        """Keep via-points within the controller's reported limits too (a station may
        configure tighter limits than the robot model's)."""
        self.q_min = np.maximum(self.q_min, np.asarray(q_min, dtype=float))
        self.q_max = np.minimum(self.q_max, np.asarray(q_max, dtype=float))

    async def move(self, robot: RobotAdapter, phase: Phase, index: int, q: np.ndarray,
                   q_from: np.ndarray | None) -> MoveOutcome | SampleRecord:
        """Move to q (n,) rad, through a via-point if the tally asks for one; as
        ``move_or_skip`` (a skipped pose is its SampleRecord)."""
        self._via = None if self.tally is None else via_point(
            self.tally, q_from, q, q_min=self.q_min, q_max=self.q_max)
        if self._via is not None:
            self.vias += 1
            first = await move_or_skip(robot, self.speed, phase, index, self._via, q_from)
            if isinstance(first, SampleRecord):
                return first
        return await move_or_skip(robot, self.speed, phase, index, q,
                                  q_from if self._via is None else self._via)

    def signs(self, q_from: np.ndarray | None, q_reached: np.ndarray) -> list[float]:
        """The recorded approach (n,) of the sample the last ``move`` reached (q_reached:
        the controller's joint angles there), counted in the tally."""
        if self._via is None:
            signs = approach_signs(q_from, q_reached)
        else:
            signs = approach_after(q_from, self._via, q_reached).tolist()
        if self.tally is not None:
            self.tally = self.tally.add(np.asarray(signs))
        return signs
