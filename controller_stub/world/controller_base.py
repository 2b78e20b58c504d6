"""The contract's state half, shared by the simulations: `ControllerBase`.

A simulation derives from it and hands it its `ControllerState`; every state call of the
`SimulatedController` contract (offsets, history, IO, e-stop, clock, limits) is answered
from that state through its methods. Motion, sensors and truth are the simulation's own.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from controller_stub.world.controller_state import ControllerState, OnIoEdge

__all__ = ["ControllerBase"]


class ControllerBase:
    """The contract's state half, answered from the simulation's `ControllerState`.

    A simulation (`Simulation`, `HumanoidSimulation`) derives from it, passes its state in,
    and adds its motion, sensors and truth as collaborators of its own. Nothing here reads
    another object's private attributes: every call goes through `state`'s methods.
    """

    def __init__(self, state: ControllerState) -> None:
        self.state = state
        self.scenario = state.scenario

    @property
    def on_io_edge(self) -> OnIoEdge | None:
        """Called for each IO edge the controller reports (set by the server)."""
        return self.state.on_io_edge

    @on_io_edge.setter
    def on_io_edge(self, callback: OnIoEdge | None) -> None:
        self.state.on_io_edge = callback

    @property
    def n_joints(self) -> int:
        return self.state.n_joints

    @property
    def time(self) -> float:
        """Simulated clock (s): see `ControllerState.time`."""
        return self.state.time

    @property
    def time_scale(self) -> float:
        return self.state.time_scale

    @property
    def estopped(self) -> bool:
        return self.state.estopped

    @property
    def busy(self) -> bool:
        return self.state.busy

    def estop(self) -> None:
        self.state.estop()

    def settle_for_measurement(self) -> float:
        """See `ControllerState.settle_for_measurement`."""
        return self.state.settle_for_measurement()

    def hold_for_capture(self) -> None:
        """The robot stands still for one measurement (settled before it,
        `settle_for_measurement`): the clock advances by the scenario's `motion.capture_s`
        (a stereo capture, a tracker reading, a kind's own sensor reading)."""
        self.state.advance_clock(float(self.state.scenario.motion.capture_s))

    def reset_estop(self) -> None:
        self.state.reset_estop()

    def joint_positions(self) -> np.ndarray:
        return self.state.joint_positions()

    def joint_limits(self) -> tuple[np.ndarray, np.ndarray]:
        return self.state.joint_limits()

    def max_joint_speed(self) -> np.ndarray:
        return self.state.max_joint_speed()

    def max_joint_acceleration(self) -> np.ndarray:
        return self.state.max_joint_acceleration()

    def zero_offsets(self) -> np.ndarray:
        return self.state.zero_offsets()

    def current_zero_errors(self) -> np.ndarray:
        return self.state.current_zero_errors()

    def set_zero_offsets(self, offsets: Any) -> np.ndarray:
        return self.state.set_zero_offsets(offsets)

    def offset_history(self) -> list[tuple[int, np.ndarray]]:
        return self.state.offset_history()

    @property
    def last_history_id(self) -> int:
        return self.state.last_history_id

    def rollback(self, history_id: int) -> np.ndarray:
        return self.state.rollback(history_id)

    def undo_write(self, history_id: int) -> np.ndarray:
        return self.state.undo_write(history_id)

    def digital_inputs(self) -> list[bool]:
        return self.state.digital_inputs()

    def digital_outputs(self) -> list[bool]:
        return self.state.digital_outputs()

    def set_digital_output(self, index: int, value: bool) -> None:
        self.state.set_digital_output(index, value)
