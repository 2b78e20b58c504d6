"""The simulated arm's body: its own forward model, its hidden physics and its backlash state.

The physical joint angles differ from the reported ones by the current zero error (from the
controller state) and by the hidden effects (`physics.py`); backlash depends on the
direction each joint last moved (`approach`, +1 or -1 per joint), which only a finished
motion changes (`note_motion`). Angles radians (reported frame), lengths metres, times
seconds of the simulated clock.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from controller_stub.world.controller_state import ControllerState
from controller_stub.world.physics import HiddenEffects, Physics
from controller_stub.world.robot_model import RobotModel


class ArmBody:
    """The arm of one simulation: model, hidden effects, physics and backlash approach.

    state: the simulation's controller state (reported angles, clock, zero errors), read
    through its methods.
    """

    def __init__(self, model: RobotModel, effects: HiddenEffects, state: ControllerState
                 ) -> None:
        self.model = model
        self.effects = effects
        self.physics = Physics(model, effects)
        self.state = state
        self._approach = np.ones(model.n_joints)

    @property
    def approach(self) -> np.ndarray:
        """(n,) direction each joint last moved (+1 / -1; +1 before any motion)."""
        return self._approach.copy()

    def approach_toward(self, q_start: np.ndarray, target: np.ndarray) -> np.ndarray:
        """(n,) the approach along a motion from q_start to target: a moving joint approaches
        in its direction, a still one keeps its last."""
        moved = np.sign(target - q_start)
        approach: np.ndarray = np.where(moved != 0, moved, self._approach)
        return approach

    def note_motion(self, q_start: np.ndarray, q_end: np.ndarray) -> None:
        """A motion from q_start to q_end (n,) happened: update the approach directions."""
        self._approach = self.approach_toward(q_start, q_end)

    def physical_angles(self, q_reported: np.ndarray | None = None) -> np.ndarray:
        """(n,) physical joint angles for reported angles (default: the current pose), with
        the current offsets, backlash state and clock."""
        state = self.state
        q = state.joint_positions() if q_reported is None else np.asarray(
            q_reported, float).reshape(-1)
        return self.physics.physical_angles(
            q[None, :], state.current_zero_errors(), self._approach, state.time
        )[0]

    def physical_along(self, q_reported: np.ndarray, approach: np.ndarray, times: Any
                       ) -> np.ndarray:
        """(K, n) physical angles of reported angles (K, n) along a motion with the given
        approach (n,) at simulated times (K,) or one time (s)."""
        return self.physics.physical_angles(
            q_reported, self.state.current_zero_errors(), approach, times)

    def flange_pose(self) -> np.ndarray:
        """(4, 4) true T_base_flange at the current pose."""
        return self.physics.flange_pose(self.physical_angles()[None, :], self.state.time)[0]
