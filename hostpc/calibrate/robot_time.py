"""Robot time: how long a calibration keeps the robot busy, per phase.

Robot time is what the robot spends on the run: motion, settling before each measurement
and the captures, for the phases that use the robot:

- `rig`: the method's preparation (stereo_target: the chessboard views of the rig
  calibration; nothing on a resume that reloads the rig);
- `measure`: the fit poses;
- `verify`: the fresh verification poses.

Each phase is timed (a clock reading after every journaled pose and at the phase's end) by
the controller's own clock when it reports one (`RobotState.extra["time"]`: the simulator's
clock, which charges motion, settle and capture time, see docs/simulator.md), else by the
host's monotonic clock (a real robot is busy for the wall time of the phase). Each reading
journals the time since the previous one (`{"event": "robot_time", "phase": ...,
"seconds": ..., "clock": "controller"|"host"}`), right after the pose's own record, so a
resumed run adds the time of every session. A controller-clock entry also journals the
reading (`"at"`): a resume whose controller clock ran on (its first reading not before the
journal's last: the same controller, not restarted) first journals the time since that
reading to the phase it was in (the move and settling into the pose being measured when
the session stopped); after a restart (a resumed `--robot sim`) or by the host's clock, a
session killed mid-phase (Ctrl-C, kill -9, power cut) loses at most that pose's time.

`robot_time_document(journal)` is result.json's `robot_time_s`: seconds per phase and
`total` (their sum), with the clock used.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping

from hostpc.calibrate.journal import Journal
from hostpc.calibrate.journal_events import RobotTimeSpent
from hostpc.json_object import JsonObject
from hostpc.robots.base import RobotAdapter, RobotState

PHASES = ("rig", "measure", "verify")


async def robot_clock(robot: RobotAdapter) -> tuple[float, str]:
    """(now in s, "controller") from the controller's clock, else (monotonic, "host")."""
    now = (await robot.state()).controller_time
    if now is not None:
        return now, "controller"
    return time.monotonic(), "host"


class RobotTimer:
    """Times the phases of one session of a run and journals them (module docstring).

    The controller's clock is read after each pose and at each phase end (one `state`
    request each): a reading counts from the previous one (the run's first `state`, then
    the last reading), so what the controller's clock counts between phases is the fit and
    the push: nothing on the simulated arm's clock (it advances only with what the arm
    does), their wall time on a UR controller's uptime (a real robot stands idle while the
    host computes, and that is robot time the plan does not predict). With the host's
    clock (free to read) `begin` restarts the count, so the fit's time is not the robot's."""

    def __init__(self, robot: RobotAdapter, journal: Journal, state: RobotState) -> None:
        self.robot = robot
        self.journal = journal
        now = state.controller_time
        if now is not None:
            self._last, self._clock = now, "controller"
            self._since_last_session(now)
        else:
            self._last, self._clock = time.monotonic(), "host"

    def _since_last_session(self, now: float) -> None:
        """On a resume whose controller clock ran on (not before the journal's last reading:
        not restarted), journal the time from that reading to `now` to the phase it was in:
        the move and settling into the pose being measured when the session stopped."""
        readings = [(event.phase, event.at) for event in self.journal.events(RobotTimeSpent)
                    if event.clock == "controller" and event.at is not None]
        if readings:
            phase, at = readings[-1]
            if at is not None and math.isfinite(at) and now > at:
                self.journal.append(RobotTimeSpent(phase=phase, seconds=now - at,
                                                   clock="controller", at=now))

    def begin(self) -> None:
        """A phase starts now (the host's clock only; the controller's is not read)."""
        if self._clock == "host":
            self._last = time.monotonic()

    async def end(self, phase: str) -> float:
        """A pose or a phase ends: read the clock, journal the phase's robot time since the
        previous reading (s)."""
        now, clock = await robot_clock(self.robot)
        last, self._last = self._last, now
        if clock != self._clock:  # the controller's clock vanished: nothing sure
            self._clock = clock
            return 0.0
        seconds = max(0.0, now - last)
        if seconds > 0.0:
            self.journal.append(RobotTimeSpent(phase=phase, seconds=seconds, clock=clock,
                                               at=now if clock == "controller" else None))
        return seconds


def robot_time_document(journal: Journal) -> JsonObject:
    """result.json's `robot_time_s`: {"rig", "measure", "verify", "total"} in s (summed
    over the run's sessions) and "clock" ("controller", "host", "mixed" or None)."""
    seconds = dict.fromkeys(PHASES, 0.0)
    clocks: set[str] = set()
    for event in journal.events(RobotTimeSpent):
        if event.phase in seconds and math.isfinite(event.seconds):
            seconds[event.phase] += event.seconds
            clocks.add(event.clock)
    clock = None if not clocks else (clocks.pop() if len(clocks) == 1 else "mixed")
    return {**seconds, "total": sum(seconds.values()), "clock": clock}


def format_robot_time(document: JsonObject) -> str | None:
    """The summary's robot time line, or None if the document has no robot time."""
    rt = document.get("robot_time_s")
    if not rt:
        return None
    source = {"controller": "controller clock", "host": "wall time on the host",
              "mixed": "controller and host clocks"}.get(str(rt.get("clock")), "not measured")
    planned = (document.get("plan") or {}).get("predicted_robot_time_s")
    against = (f"; planned {planned['total']:.1f} s for measure + verify, floor "
               f"{planned['floor']:.1f} s" if isinstance(planned, Mapping) else "")
    return (f"robot time: {rt['total']:.1f} s (rig {rt['rig']:.1f}, measure "
            f"{rt['measure']:.1f}, verify {rt['verify']:.1f}; {source}{against})")
