"""The UR personality's controller uptime: the RTDE `timestamp` its packages carry.

A real controller's uptime runs with the wall clock, whatever the arm does, and every
second the arm spends moving, settling or being measured is a second of it. The simulation
charges those seconds to its own clock (`SimulatedController.time`: motions, settling,
captures) whether or not it spends them in wall time: at time_scale 0 a move takes no wall
time at all, and a capture never does. The uptime is therefore

    uptime = CYCLE_S per controller cycle (about the wall time that passes: the arm
             stands still while the host computes, as a real one does; a loaded
             machine slows the cycle clock, which never skips a cycle, so then the
             uptime runs slower than the wall clock)
           + every advance of the simulated clock, less the cycles that paced it (a
             motion shown in wall time, by the personality or the zerocal server)

so a simulated second is counted once, at time_scale 0 as at 1, and the uptime never runs
backwards (an advance smaller than its pacing adds nothing). While the arm stands still
(no motion paced, the simulated clock not advancing) the cycle's wall time counts toward
its settling too (`ControllerState.stand_still`): a measurement after the host computed for
a while settles no longer than the rest it still needs, on the controller's clock.

A frozen controller's uptime stands still: the host's dead-controller check
(`hostpc.robots.ur_link`, no new RTDE sample for `--timeout` s) sees it.
"""

from __future__ import annotations

from controller_stub.ur.paced_motion import CYCLE_S
from controller_stub.world.controller_state import ControllerState


class ControllerUptime:
    """The uptime (s) of a controller on the simulation's `state` (module docstring),
    advanced once per controller cycle by `tick`."""

    def __init__(self, state: ControllerState) -> None:
        self.state = state
        self._ticked = 0.0  # the uptime (s) up to the last cycle
        self._sim_seen = state.time
        self._paced = 0.0  # wall time (s) of the cycles pacing a motion not yet charged

    @property
    def seconds(self) -> float:
        """The uptime (s), what RTDE `timestamp` shows: up to the last cycle, and the
        simulated time charged since (a move's end, a settle, a capture) at once, so that a
        sample that shows the arm where a move ended shows that move's time too (before,
        it showed at the next cycle, and a host that read the end sooner on a loaded
        machine took the move's time as none and its rest as begun before the move)."""
        return self._ticked + self._uncounted(self.state.time - self._sim_seen)

    def _uncounted(self, charged: float) -> float:
        """Of `charged` simulated seconds, those the cycles that paced them did not count."""
        return max(0.0, charged - self._paced) if charged > 0.0 else 0.0

    def tick(self, pacing: bool) -> None:
        """One controller cycle passed; `pacing`: a motion was shown in wall time during it
        (its simulated time is charged when it ends)."""
        charged = self.state.time - self._sim_seen
        self._sim_seen = self.state.time
        if charged > 0.0:
            self._ticked += self._uncounted(charged)
            self._paced = max(0.0, self._paced - charged)
        if pacing:
            self._paced += CYCLE_S
        else:
            self._paced = 0.0
            if charged <= 0.0:  # the arm stood still this cycle
                self.state.stand_still(CYCLE_S)
        self._ticked += CYCLE_S
