"""Guarded moves of the UR driver for the touch probe: an asynchronous moveJ watched sample by
sample over RTDE, stopped with stopJ at the probe input's rising edge (docs/ur-probe.md).

`UrGuardedMove` is a collaborator of `hostpc.robots.ur.UrAdapter`: it moves through the
adapter's `UrLink` (ur_rtde, the motion lock) and converts angles with its `UrHostOffsets`,
and owns the latch timings of the session. Each RTDE sample carries the joint angles and the
input bits of one controller cycle; the latch is the midpoint of the edge window (the last
sample with the input low, the first with it high) and every contact's timing is kept as a
`LatchTiming`. Angles rad, times s.
"""

from __future__ import annotations

import asyncio
import logging
import math
import threading
import time
from dataclasses import dataclass

import numpy as np

from hostpc.errors import InputError
from hostpc.robots.base import ContactOutcome
from hostpc.robots.ur_link import (
    JOINT_ACCELERATION,
    MAX_JOINT_SPEED,
    FreshSamples,
    Sample,
    UrLink,
    at_target,
    check_joints,
    joint_velocity,
)
from hostpc.robots.ur_offsets import UrHostOffsets

logger = logging.getLogger("hostpc.robots.ur")

N_DIGITAL_IO = 16
"""Standard (0-7) and configurable (8-15) digital IO, bit i of the RTDE IO bit words."""
STOP_DECELERATION = 10.0
"""rad/s^2 of the stopJ after a probe edge (ur_rtde's default is 2.0; a harder stop shortens
the overtravel)."""
POLL_INTERVAL_S = 0.0002
"""Pause between two reads of the RTDE sample by a guarded move (a 500 Hz stream: 2 ms)."""
MAX_LATCH_RETRIES = 3
"""A contact whose edge window missed samples is measured again, at most this often; if
every attempt missed samples the contact is reported missed (`edge_window_missed_samples`)."""
RETRY_SPEED = 0.3
"""Speed fraction of the move back to the start before a retried contact."""


def rtde_frequency(controller_version: tuple[int, ...]) -> float:
    """The RTDE rate ur_rtde uses: 500 Hz on e-Series (controller 5.x), else 125 Hz."""
    return 500.0 if controller_version[0] >= 5 else 125.0


@dataclass(frozen=True)
class LatchTiming:
    """The timing of one probe contact, as measured by the UR guarded move.

    edge_window_s: controller time between the last sample with the input low and the first
    with it high (one sample period unless samples were missed); sample_period_s: the
    smallest sample spacing seen during the move; stop_command_s: host time from seeing the
    edge to stopJ returning; overtravel_rad: largest joint travel from the edge sample to
    standstill; attempt: 0, or the retry that gave this contact.
    """

    edge_window_s: float
    sample_period_s: float
    stop_command_s: float
    overtravel_rad: float
    attempt: int = 0

    @property
    def missed_samples(self) -> int:
        """Samples the host did not read inside the edge window."""
        return max(0, round(self.edge_window_s / max(self.sample_period_s, 1e-9)) - 1)


@dataclass(frozen=True)
class _Watch:
    """What the guarded move's watcher saw: edge (last low, first high sample) or None,
    the last sample, the smallest sample spacing (s), host time of the stopJ call (s)."""

    edge: tuple[Sample, Sample] | None
    last: Sample
    period: float
    stop_command_s: float


class UrGuardedMove:
    """guarded_move and the latch timing of a UR session (see the module docstring).
    link: the RTDE link; offsets: the host zero offsets (reported = UR angles + offsets);
    rtde_frequency: Hz of the RTDE stream (a sample period when none was measured)."""

    def __init__(self, link: UrLink, offsets: UrHostOffsets, rtde_frequency: float) -> None:
        self.link = link
        self.offsets = offsets
        self.rtde_frequency = rtde_frequency
        self.latches: list[LatchTiming] = []
        """Timing of every probe contact of this session."""

    async def guarded_move(self, q: np.ndarray, speed: float, io_line: int) -> ContactOutcome:
        """Asynchronous moveJ toward q (6,) watching digital input `io_line` in every RTDE
        sample; at its rising edge the robot is stopped (stopJ) and the joint angles at the
        edge latched (docs/ur-probe.md).

        Each RTDE sample carries the angles and the input bits of one controller cycle, so
        the edge lies between the last sample with the input low and the first with it
        high: q_latched is the midpoint of those two samples' angles (the edge's expected
        position; the constant part of the probe's latency is fitted by `trigger_latency`,
        the uniform spread of +-half a window adds `latch_jitter_s`). The samples are read
        by one worker thread for the whole move (no event-loop round trip per sample). A
        contact whose edge window spans more than one sample period (samples the host did
        not read in time) is measured again from the start, up to MAX_LATCH_RETRIES times.
        The timing of every contact is kept in `self.latches` and logged.
        """
        if not 0 <= int(io_line) < N_DIGITAL_IO:
            raise InputError(f"io_line {io_line}: expected 0..{N_DIGITAL_IO - 1}")
        link = self.link
        target = self.offsets.to_ur(check_joints(q))
        velocity = joint_velocity(speed)
        async with link.motion_lock:
            for attempt in range(MAX_LATCH_RETRIES + 1):
                try:  # the touch is a measurement: the arm stands still first
                    await link.settle()
                except asyncio.CancelledError as exc:  # Ctrl-C, SIGTERM before the approach
                    logger.info("UR %s: guarded_move interrupted while settling", link.host)
                    exc.add_note("guarded_move interrupted while settling: arm at rest, "
                                 "no stop needed")
                    raise
                start = await link.call(link.sample)
                if start[2] >> io_line & 1:
                    return ContactOutcome(False, None, self.offsets.reported(start[1]),
                                          reason="probe_already_triggered")
                op0 = (await link.call(link.control.getAsyncOperationProgressEx)).operationId()
                command = asyncio.ensure_future(link.call(
                    link.control.moveJ, target.tolist(), velocity, JOINT_ACCELERATION, True))
                cancel = threading.Event()
                watching: asyncio.Future[_Watch] | None = None
                try:
                    ok = await asyncio.shield(command)
                    if ok:
                        watching = asyncio.ensure_future(
                            link.call(self._watch, io_line, start, op0, cancel))
                        watch = await asyncio.shield(watching)
                except asyncio.CancelledError as exc:  # Ctrl-C, SIGTERM: stop the arm
                    cancel.set()
                    await link.interrupted(exc, "guarded_move", target, command, watching)
                    raise
                if not ok:
                    reason = await link.failure_reason()
                    _, q_now, _, _ = await link.call(link.sample)
                    return ContactOutcome(False, None, self.offsets.reported(q_now),
                                          reason=reason)
                if watch.edge is None:
                    # the controller ended the move (dashboard stop, protective stop, ...):
                    # the arm stands where it stopped; otherwise the move ran to its end
                    ended = await link.failure_reason(None)
                    measured = await link.fresh_q(watch.last[0] - 1e-9,
                                                  None if ended else target)
                    if ended is None and not at_target(measured, target):
                        # short of the target: the controller's flags may have come late
                        ended = await link.failure_reason(None)
                    await link.came_to_rest()
                    return ContactOutcome(False, None, self.offsets.reported(measured),
                                          reason=ended or "no_contact")
                low, high = watch.edge
                q_stop = await link.fresh_q(high[0], None)
                await link.came_to_rest()
                latch = LatchTiming(
                    edge_window_s=high[0] - low[0],
                    sample_period_s=(watch.period if math.isfinite(watch.period)
                                     else 1.0 / self.rtde_frequency),
                    stop_command_s=watch.stop_command_s,
                    overtravel_rad=float(np.max(np.abs(q_stop - high[1]))),
                    attempt=attempt,
                )
                self.latches.append(latch)
                logger.info("UR %s: probe edge within %.1f ms (%d sample(s) missed), stopJ "
                            "took %.1f ms, overtravel %.2e rad", link.host,
                            1e3 * latch.edge_window_s, latch.missed_samples,
                            1e3 * latch.stop_command_s, latch.overtravel_rad)
                if latch.missed_samples == 0:
                    q_latched = 0.5 * (low[1] + high[1])
                    return ContactOutcome(True, self.offsets.reported(q_latched),
                                          self.offsets.reported(q_stop),
                                          qd=(high[1] - low[1]) / latch.edge_window_s)
                back = await link.move(start[1], RETRY_SPEED * MAX_JOINT_SPEED)
                if not back.completed:
                    break
            # every attempt missed samples at the edge: no contact of known precision
            return ContactOutcome(False, None, self.offsets.reported(q_stop),
                                  reason="edge_window_missed_samples")

    def _watch(self, io_line: int, start: Sample, op0: int, cancel: threading.Event
               ) -> _Watch:
        """Blocking (a worker thread): read every new RTDE sample of the asynchronous move
        until the input rises (stopJ at once), the move ends (an operation after `op0`, the
        one before the moveJ, ran and ended: a move that takes no wall time may have ended
        before the watch began), or `cancel` is set (the caller stops the arm).
        ConnectionFailed when no new sample came for the link's timeout (a dead or frozen
        controller: ur_rtde repeats its last state; `FreshSamples`)."""
        low = start
        fresh = FreshSamples(self.link)
        period = math.inf
        deadline = time.monotonic() + max(self.link.timeout, 60.0)
        next_status = 0.0
        started = False
        while True:
            sample = self.link.sample()
            if sample[0] > low[0]:
                if sample[2] >> io_line & 1:
                    seen = time.monotonic()
                    self.link.control.stopJ(STOP_DECELERATION, False)
                    return _Watch((low, sample), sample, min(period, sample[0] - low[0]),
                                  time.monotonic() - seen)
                if low is not start:
                    period = min(period, sample[0] - low[0])
                low = sample
            now = time.monotonic()
            if now >= next_status:  # the move's end, checked every few cycles
                next_status = now + 0.005
                status = self.link.control.getAsyncOperationProgressEx()
                started = started or status.operationId() != op0
                if started and not status.isAsyncOperationRunning():
                    final = self.link.sample()
                    if not final[2] >> io_line & 1:
                        return _Watch(None, final, period, 0.0)
                    continue  # the edge came with the last samples
            if cancel.is_set():
                return _Watch(None, sample, period, 0.0)
            fresh.check(sample[0])
            if now > deadline:
                self.link.control.stopJ(STOP_DECELERATION, False)
                raise RuntimeError("guarded move did not end")
            time.sleep(POLL_INTERVAL_S)

    @property
    def latch_jitter_s(self) -> float:
        """One-sigma timing spread of a latched edge (s): the RTDE sample period / sqrt(12)
        (the edge is uniform within one sample window)."""
        return 1.0 / (self.rtde_frequency * math.sqrt(12.0))

    def latch_summary(self) -> str | None:
        """One line on the probe latches of this session (None without contacts)."""
        if not self.latches:
            return None
        window = np.array([latch.edge_window_s for latch in self.latches])
        stop = np.array([latch.stop_command_s for latch in self.latches])
        retried = sum(1 for latch in self.latches if latch.attempt > 0)  # repeated contacts
        return (
            f"UR probe latch: {len(self.latches)} edges, window median "
            f"{1e3 * np.median(window):.1f} ms (max {1e3 * window.max():.1f} ms, "
            f"{retried} retries), latch jitter "
            f"{1e3 * self.latch_jitter_s:.2f} ms, stopJ median {1e3 * np.median(stop):.1f} ms, "
            f"overtravel max {max(latch.overtravel_rad for latch in self.latches):.2e} rad"
        )
