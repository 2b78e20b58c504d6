"""The UR guarded move's latch (hostpc/robots/ur_guarded.py) against a scripted stand-in for
ur_rtde's receive / control interfaces (no sockets): a controller that advances one cycle
every PERIOD_S of wall time, moves at constant joint speed and raises the probe input at a
known cycle. The real library against the stub is tested in
tests/integration/test_ur_probe.py."""

from __future__ import annotations

import asyncio
import logging
import threading
import time
from dataclasses import dataclass

import numpy as np
import pytest

from hostpc.robots import ur_link
from hostpc.robots.ur import UrAdapter
from hostpc.robots.ur_precheck import UrControllerInfo

PERIOD_S = 0.02
"""A slow controller cycle, so the watcher thread reads every sample even on a busy host."""
SPEED = np.array([0.1, -0.05, 0.0, 0.02, 0.0, 0.0])
"""rad per controller second."""


@dataclass
class _Status:
    op: int
    running: bool

    def operationId(self) -> int:  # noqa: N802 (ur_rtde's name)
        return self.op

    def isAsyncOperationRunning(self) -> bool:  # noqa: N802
        return self.running


class ScriptedUr:
    """receive + control of a controller whose input rises `edge_after` cycles into a move;
    hide_cycle_before_edge: the sample of the cycle before the edge is never shown. A move
    to the start pose (zeros: the move back before a retried contact) is there at once."""

    def __init__(self, edge_after: int = 7, hide_cycle_before_edge: bool = False) -> None:
        self.t0 = time.monotonic()
        self.edge_after = edge_after
        self.hide = hide_cycle_before_edge
        self.lock = threading.Lock()
        self.start: int | None = None
        self.stop: int | None = None
        self.base = np.zeros(6)
        self.op = 0
        self.moves = 0

    def _cycle(self) -> int:
        cycle = int((time.monotonic() - self.t0) / PERIOD_S)
        if self.hide and self.start is not None and cycle == self.start + self.edge_after - 1:
            cycle -= 1
        return cycle

    def _state(self, cycle: int) -> tuple[np.ndarray, int]:
        with self.lock:
            if self.start is None:
                return self.base.copy(), 0
            end = cycle if self.stop is None else min(cycle, self.stop)
            moved = max(0, end - self.start)
            return self.base + SPEED * moved * PERIOD_S, int(moved >= self.edge_after)

    # receive
    def getTimestamp(self) -> float:  # noqa: N802
        return self._cycle() * PERIOD_S

    def getActualQ(self) -> list[float]:  # noqa: N802
        return self._state(self._cycle())[0].tolist()

    def getActualDigitalInputBits(self) -> int:  # noqa: N802
        return self._state(self._cycle())[1]

    def getActualDigitalOutputBits(self) -> int:  # noqa: N802
        return 0

    def isEmergencyStopped(self) -> bool:  # noqa: N802
        return False

    def isProtectiveStopped(self) -> bool:  # noqa: N802
        return False

    def isProgramRunning(self) -> bool:  # noqa: N802
        return True

    def isConnected(self) -> bool:  # noqa: N802
        return True

    # control
    def moveJ(self, q: list[float], speed: float, acceleration: float,  # noqa: N802
              asynchronous: bool = False) -> bool:
        with self.lock:
            if self.start is not None:  # a new move starts where the last one stopped
                end = self._cycle() if self.stop is None else self.stop
                self.base = self.base + SPEED * max(0, end - self.start) * PERIOD_S
            self.op += 1
            if not np.any(q):  # the move back to the start (zeros): instantly there
                self.base, self.start, self.stop = np.asarray(q, float), None, None
                return True
            self.start, self.stop = self._cycle(), None
            self.moves += 1
        return True

    def stopJ(self, deceleration: float, asynchronous: bool = False) -> None:  # noqa: N802
        with self.lock:
            self.stop = self._cycle() + 1

    def getAsyncOperationProgressEx(self) -> _Status:  # noqa: N802
        return _Status(self.op, self.start is not None and self.stop is None)


def _adapter(ur: ScriptedUr) -> UrAdapter:
    info = UrControllerInfo((5, 11, 1, 0), "URSoftware 5.11", "UR5", "", True)
    return UrAdapter("127.0.0.1", info, ur, ur, io=None, timeout=5.0)


def test_the_latch_is_the_midpoint_of_the_edge_window_and_the_robot_stops() -> None:
    ur = ScriptedUr(edge_after=7)
    adapter = _adapter(ur)
    outcome = asyncio.run(adapter.guarded_move(np.full(6, 0.5), 0.05, 0))
    assert outcome.contact and outcome.q_latched is not None and outcome.qd is not None
    # the input rose between cycles 6 and 7 of the move: the latch is at 6.5 cycles
    np.testing.assert_allclose(outcome.q_latched, SPEED * 6.5 * PERIOD_S, atol=1e-12)
    np.testing.assert_allclose(outcome.qd, SPEED, rtol=1e-9)
    latch = adapter.latches[-1]
    assert latch.edge_window_s == pytest.approx(PERIOD_S)
    assert latch.missed_samples == 0 and latch.attempt == 0
    assert np.max(np.abs(outcome.q - outcome.q_latched)) < 0.05  # stopped soon after
    assert adapter.latch_jitter_s == pytest.approx(1 / (500 * np.sqrt(12)))
    assert "1 edges" in (adapter.latch_summary() or "")


def test_a_window_that_missed_samples_is_measured_again_then_reported_missed() -> None:
    ur = ScriptedUr(edge_after=7, hide_cycle_before_edge=True)
    adapter = _adapter(ur)
    outcome = asyncio.run(adapter.guarded_move(np.full(6, 0.5), 0.05, 0))
    assert not outcome.contact and outcome.q_latched is None
    assert outcome.reason == "edge_window_missed_samples"
    assert ur.moves == 4  # MAX_LATCH_RETRIES + 1 attempts
    assert [latch.missed_samples for latch in adapter.latches] == [1, 1, 1, 1]


def test_an_input_already_high_refuses_to_move() -> None:
    ur = ScriptedUr(edge_after=0)
    ur.start = ur._cycle()  # a move long ago left the probe pressed
    ur.stop = ur.start
    adapter = _adapter(ur)
    outcome = asyncio.run(adapter.guarded_move(np.full(6, 0.5), 0.05, 0))
    assert not outcome.contact and outcome.reason == "probe_already_triggered"


def test_a_cancelled_guarded_move_stops_the_arm() -> None:
    """Ctrl-C / SIGTERM (the run's task cancelled) during a guarded move: the watcher thread
    lets go, the arm is stopped with stopJ, and the cancellation carries a note saying so
    (before, the watcher ran on until the input rose or its 60 s deadline)."""
    ur = ScriptedUr(edge_after=10_000)  # no contact
    adapter = _adapter(ur)

    async def cancel_mid_move() -> asyncio.CancelledError:
        task = asyncio.create_task(adapter.guarded_move(np.full(6, 0.5), 0.05, 0))
        await asyncio.sleep(10 * PERIOD_S)
        assert ur.start is not None and ur.stop is None  # moving
        task.cancel()
        with pytest.raises(asyncio.CancelledError) as caught:
            await task
        return caught.value

    exc = asyncio.run(cancel_mid_move())
    assert ur.stop is not None
    q = np.array(ur.getActualQ())
    time.sleep(3 * PERIOD_S)
    np.testing.assert_array_equal(ur.getActualQ(), q)  # at rest
    short = np.degrees(np.max(np.abs(0.5 - q)))
    assert exc.__notes__ == [f"guarded_move interrupted: stopJ sent: motion stopped "
                             f"{short:.1f} deg short of the target"]


class _StopHangs(ScriptedUr):
    """A controller that never answers stopJ (a frozen one)."""

    def __init__(self) -> None:
        super().__init__()
        self.release = threading.Event()

    def stopJ(self, deceleration: float, asynchronous: bool = False) -> None:  # noqa: N802
        self.release.wait(5.0)


def test_a_stopj_that_times_out_logs_the_error_type(monkeypatch: pytest.MonkeyPatch,
                                                    caplog: pytest.LogCaptureFixture) -> None:
    """str(TimeoutError()) is empty: the log line names the type instead."""
    monkeypatch.setattr(ur_link, "STOP_TIMEOUT_S", 0.2)
    ur = _StopHangs()
    adapter = _adapter(ur)
    with caplog.at_level(logging.WARNING, logger="hostpc.robots.ur"):
        said = asyncio.run(adapter.link.stop_interrupted(np.full(6, 0.5)))
    ur.release.set()
    assert said == "stopJ sent, not confirmed"
    assert "stopJ after an interrupted move failed: TimeoutError" in caplog.text
