"""The simulated controller's asyncio TCP server: a thin shell around one `Simulation`.

Each client gets a sans-IO `protocol.Connection` (handshake, auth and malformed input are
handled there) and a reader loop; every accepted request runs as its own task, so `abort`,
`heartbeat` and state reads are answered while a motion is in progress. Any failure of a
handler becomes an `error` reply (`refused` with the simulation's reason for
`SimulationRefused`, `internal` otherwise) and the server keeps serving; a client that
breaks the framing gets an error reply and its connection closed, nobody else notices.

Motions are paced in wall time: the simulation plans the move (`sim.begin_move`), the
server waits `duration_s * time_scale` and then executes it (`sim.finish_move`). An `abort`
ends the wait early and the robot stops where it was: at the elapsed fraction of the motion,
with only the IO edges (and a guarded contact) that came before the stop. While a motion
runs, `get_state` reports the joint angles interpolated along the path. One motion at a time
for the whole controller: a second one is refused with `busy`, and so are offset writes.

Limits against slow, stalled, greedy or hostile peers (all per `ControllerServer`
arguments, from `scenario.server`): a client must say hello AND authenticate within
`handshake_timeout_s` of connecting (heartbeats do not extend it; a session without a token
gets that long for its reads), and a frame it has started must be complete within the same
time; a session that sends nothing for `idle_timeout_s` while no request of its own is in
flight is closed (a heartbeat keeps it alive); at most `max_sessions` sessions, of which at
most `max_unauthenticated_sessions` not yet authenticated: a newcomer evicts the oldest
unauthenticated session (an error reply `busy`, then close; from the address holding the
most, loiterers first: `protocol.admission.SessionSlots`), so an operator with the
token always gets in; only when every slot holds an authenticated session is the newcomer
refused (an error reply, then the connection closes). Failed authentications slow down
every later session from the same peer address (`protocol.admission.AuthThrottle`);
at most `max_requests_in_flight` requests per session run at once (beyond that the server
stops reading from that client: backpressure); the server also stops reading while the
client's unsent replies exceed `WRITE_HIGH_WATER` bytes, and drops a client that has not
read them for `idle_timeout_s`. Until a session is authenticated its frames may
not exceed `PRE_AUTH_MAX_FRAME_SIZE` (requests carry no attachments).

Injected faults (scenario.faults) handled here: `drop_after_requests` (the request with that
0-based index, counted over all connections, is not executed and its connection is dropped,
once) and `reply_delay_s` (every reply waits that long in wall time). Refused moves, lost IO
edges and the e-stop live in the simulation.

IO edges reported by the simulation are pushed as `io_edge` events to every authenticated
session. The server binds 127.0.0.1 unless told otherwise.

This module holds `ControllerServer` (accepting, the session limit, motion pacing, rollback
ids, the truth file); one client connection is a `session.Session`, and its request handlers
are in `handlers.py`; the session's limits (frame sizes, buffers) are `session.py`'s.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import os
import tempfile
from collections.abc import Iterable
from pathlib import Path

import numpy as np

from controller_stub.network.handlers import RequestRefusedError, float_list, json_default
from controller_stub.network.session import (
    CLOSE_DRAIN_S,
    SESSION_READ_CHUNK,
    Session,
)
from controller_stub.scenario.spec import Scenario
from controller_stub.sensors.registry import SimSensors, sensor_factories
from controller_stub.world.controller_state import SimulatedController
from controller_stub.world.motion import GuardedMoveResult, MotionPlan, MoveResult
from controller_stub.world.simulation import Simulation, create_simulation
from protocol import messages as m
from protocol.admission import AuthThrottle, LogBudget, SessionSlots
from protocol.connection import Connection
from protocol.errors import ErrorCode
from protocol.framing import DEFAULT_MAX_FRAME_SIZE
from protocol.session_states import Role

logger = logging.getLogger(__name__)

DEFAULT_HOST = "127.0.0.1"
READ_CHUNK = 1 << 20
REFUSAL_LOG_INTERVAL_S = 10.0
"""Refused sessions are logged once per reason in this interval (s), with a count."""


class ControllerServer:
    """Serve one simulation to many clients over the zerocal protocol.

    sim: a simulated controller (`controller_stub.world.controller_state.SimulatedController`).
    token: the shared secret clients prove with HMAC. max_frame_size: largest frame
    accepted from an authenticated client (bytes). drop_after_requests / reply_delay_s:
    injected faults (see the module docstring). truth_out: file rewritten with `sim.truth()`
    as JSON at start and whenever the offsets change. handshake_timeout_s, idle_timeout_s
    (s), max_sessions, max_unauthenticated_sessions, max_requests_in_flight: the limits of
    the module docstring. sensors: the kinds' own simulated sensors (`sensor_read`,
    controller_stub/sensors/registry.py; default: none).
    """

    def __init__(
        self,
        sim: SimulatedController,
        *,
        token: str,
        max_frame_size: int = DEFAULT_MAX_FRAME_SIZE,
        drop_after_requests: int | None = None,
        reply_delay_s: float = 0.0,
        truth_out: str | Path | None = None,
        handshake_timeout_s: float = 5.0,
        idle_timeout_s: float = 300.0,
        max_sessions: int = 32,
        max_unauthenticated_sessions: int = 16,
        max_requests_in_flight: int = 8,
        sensors: SimSensors | None = None,
    ) -> None:
        if not token:
            raise ValueError("the controller needs a non-empty token")
        self.sim = sim
        self.token = token
        self.max_frame_size = max_frame_size
        self.handshake_timeout_s = float(handshake_timeout_s)
        self.idle_timeout_s = float(idle_timeout_s)
        self.max_sessions = int(max_sessions)
        self.max_unauthenticated_sessions = max(1, int(max_unauthenticated_sessions))
        self.sessions_evicted = 0
        self.auth_throttle = AuthThrottle(max_wait_s=self.handshake_timeout_s / 2)
        self.max_requests_in_flight = max(1, int(max_requests_in_flight))
        self.sessions_refused = 0
        self.drop_after_requests = drop_after_requests
        self.reply_delay_s = reply_delay_s
        self.truth_out = Path(truth_out) if truth_out else None
        self.sensors = sensors if sensors is not None else SimSensors({}, None, {}, 0)
        self.requests_seen = 0
        self._dropped = False
        self._server: asyncio.Server | None = None
        self._refusals_logged = LogBudget(interval_s=REFUSAL_LOG_INTERVAL_S)  # per reason
        self._sessions: SessionSlots[Session] = SessionSlots(
            self.max_sessions, self.max_unauthenticated_sessions
        )
        self._motion: asyncio.Future[None] | None = None
        # the planned motion being paced: (plan, loop time at its start, wall duration s)
        self._progress: tuple[MotionPlan, float, float] | None = None
        sim.on_io_edge = self._on_io_edge

    @classmethod
    def from_scenario(
        cls, scenario: Scenario, truth_out: str | Path | None = None,
        sensor_folders: Iterable[str | Path] = (),
    ) -> ControllerServer:
        """Build the simulation of `scenario` and a server with its token and faults, and
        its simulated sensors: the installed ones and those of `sensor_folders` (a kind's
        folder with its `sim_sensor.py`), measuring the arm (not the humanoid)."""
        sim = create_simulation(scenario)
        sensors = SimSensors(sensor_factories(sensor_folders),
                             sim if isinstance(sim, Simulation) else None,
                             scenario.sensors, scenario.seed)
        return cls(
            sim,
            token=scenario.server.token,
            max_frame_size=scenario.server.max_frame_bytes,
            drop_after_requests=scenario.faults.drop_after_requests,
            reply_delay_s=scenario.faults.reply_delay_s,
            truth_out=truth_out,
            handshake_timeout_s=scenario.server.handshake_timeout_s,
            idle_timeout_s=scenario.server.idle_timeout_s,
            max_sessions=scenario.server.max_sessions,
            max_unauthenticated_sessions=scenario.server.max_unauthenticated_sessions,
            max_requests_in_flight=scenario.server.max_requests_in_flight,
            sensors=sensors,
        )

    # ----------------------------------------------------------------------- lifecycle

    async def start(self, host: str = DEFAULT_HOST, port: int = 0) -> tuple[str, int]:
        """Bind and start accepting; returns the bound (host, port) (port 0 = any free)."""
        self._server = await asyncio.start_server(
            self._accept, host, port, limit=READ_CHUNK, reuse_address=True
        )
        self.write_truth()
        bound = self.address
        logger.info("listening on %s:%d", *bound)
        return bound

    @property
    def address(self) -> tuple[str, int]:
        """The bound (host, port)."""
        if self._server is None or not self._server.sockets:
            raise RuntimeError("server not started")
        host, port = self._server.sockets[0].getsockname()[:2]
        return host, port

    async def serve_forever(self) -> None:
        """Serve until cancelled."""
        if self._server is None:
            raise RuntimeError("call start() first")
        await self._server.serve_forever()

    async def close(self) -> None:
        """Stop accepting, drop every session and cancel their requests."""
        if self._server is not None:
            self._server.close()
        for session in self._sessions:
            session.abort()
        for session in self._sessions:
            await session.finished()
        if self._server is not None:
            with contextlib.suppress(Exception):
                await self._server.wait_closed()

    async def __aenter__(self) -> ControllerServer:
        if self._server is None:
            await self.start()
        return self

    async def __aexit__(self, *exc_info: object) -> None:
        await self.close()

    @property
    def session_count(self) -> int:
        """Connected clients."""
        return len(self._sessions)

    # ---------------------------------------------------------------------- internals

    async def _accept(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        session = Session(self, reader, writer)
        wait = self.auth_throttle.reserve(session.host, self._now())
        if wait is None:
            await self._refuse_session(
                reader,
                writer,
                f"too many failed authentications from {session.host}; try again later",
            )
            return
        admitted, evicted = self._sessions.admit(session, session.host)
        for old in evicted:
            self.sessions_evicted += 1
            old.evict(f"evicted for a newer connection: at most "
                      f"{self.max_unauthenticated_sessions} sessions may be unauthenticated "
                      f"(and {self.max_sessions} in all)")
        if not admitted:
            await self._refuse_session(
                reader,
                writer,
                f"too many sessions: the controller serves at most {self.max_sessions}; "
                "try again later",
            )
            return
        try:
            await session.run(wait)
        finally:
            self._sessions.remove(session)

    def _now(self) -> float:
        return asyncio.get_running_loop().time()

    def session_authenticated(self, session: Session) -> None:
        """`session` proved the token: it keeps its slot. Its address's failures are not
        forgotten (they decay by time only: another peer on that address may be guessing)."""
        self._sessions.authenticated(session)

    def session_loitering(self, session: Session) -> None:
        """`session` made a request before authenticating: evicted before the others."""
        self._sessions.loitering(session)

    def authentication_failed(self, session: Session) -> None:
        """`session` sent a wrong proof: slow down its address."""
        self.auth_throttle.failed(session.host, self._now())

    def _log_refusal(self, peer: object, why: str) -> None:
        """One warning per reason every REFUSAL_LOG_INTERVAL_S (with the count of those not
        logged since), so that a peer hammering the server cannot flood the log."""
        suppressed = self._refusals_logged.admit(why, self._now())
        if suppressed is None:
            return
        more = f" ({suppressed} more refused for this since the last report)" if suppressed else ""
        logger.warning("refusing %s: %s%s", peer, why, more)

    async def _refuse_session(
        self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter, why: str
    ) -> None:
        """No session for this client: one `busy` error reply, then close."""
        self.sessions_refused += 1
        self._log_refusal(writer.get_extra_info("peername"), why)
        conn = Connection(Role.SERVER, token=self.token)
        error = conn.send_error(None, ErrorCode.BUSY, why)
        try:
            writer.write(error)
            writer.write_eof()
            # wait (briefly) for the client to close, discarding what it sends, so that
            # closing does not reset the connection before it has read the error
            async with asyncio.timeout(CLOSE_DRAIN_S):
                while await reader.read(SESSION_READ_CHUNK):
                    pass
        except (TimeoutError, ConnectionError, OSError):
            pass
        finally:
            writer.transport.abort()

    def count_request(self) -> bool:
        """Count one request; True if the drop fault says to drop its connection now."""
        index = self.requests_seen
        self.requests_seen += 1
        if self.drop_after_requests is not None and not self._dropped:
            if index >= self.drop_after_requests:
                self._dropped = True
                return True
        return False

    def _on_io_edge(self, line: int, value: bool, time: float, q_latched: np.ndarray) -> None:
        event = m.IoEdge(
            line=int(line), value=bool(value), time=float(time), q_latched=float_list(q_latched)
        )
        for session in self._sessions:
            session.push(event)

    def write_truth(self) -> None:
        """Rewrite the --truth-out file atomically (no-op without one)."""
        if self.truth_out is None:
            return
        truth = self.sim.truth()
        if self.sensors.truth():  # the kinds' sensors that have been read
            truth["sensors"] = self.sensors.truth()
        text = json.dumps(truth, indent=2, default=json_default)
        directory = self.truth_out.parent
        directory.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=directory, prefix=".truth-", suffix=".json")
        with os.fdopen(fd, "w", encoding="utf-8") as handle:
            handle.write(text)
        os.replace(tmp, self.truth_out)

    def mode(self) -> str:
        """Controller mode for the state reply."""
        if self.sim.estopped:
            return "estop"
        return "moving" if self._motion is not None else "idle"

    def joint_positions(self) -> np.ndarray:
        """(n,) reported joint angles now: along the path while a planned motion runs."""
        progress = self._progress
        if progress is None:
            return np.asarray(self.sim.joint_positions(), dtype=float)
        plan, started, wall = progress
        elapsed = asyncio.get_running_loop().time() - started
        return np.asarray(plan.q_at(elapsed / wall if wall > 0.0 else 1.0), dtype=float)

    async def execute_motion(self, plan: MotionPlan) -> MoveResult | GuardedMoveResult:
        """Pace `plan` (from `sim.begin_move`) in wall time, then finish it in the simulation:
        at its end, or at the elapsed fraction if it was aborted (or cancelled: shutdown).
        Returns the simulation's MoveResult / GuardedMoveResult."""
        loop = asyncio.get_running_loop()
        wall = max(0.0, float(plan.duration_s) * float(self.sim.time_scale))
        started = loop.time()
        self._progress = (plan, started, wall)
        finished = False
        try:
            finished = await self.run_motion(plan.duration_s)
        finally:
            self._progress = None
            fraction = 1.0 if finished or wall <= 0.0 else (loop.time() - started) / wall
            result = self.sim.finish_move(plan, min(fraction, 1.0))
        return result

    async def run_motion(self, duration_s: float) -> bool:
        """Pace a motion in wall time; False if it was aborted before the end."""
        loop = asyncio.get_running_loop()
        waiter: asyncio.Future[None] = loop.create_future()
        self._motion = waiter
        try:
            wall = max(0.0, float(duration_s) * float(self.sim.time_scale))
            done, _ = await asyncio.wait({waiter}, timeout=wall)
            return waiter not in done
        finally:
            if self._motion is waiter:
                self._motion = None
            if not waiter.done():
                waiter.cancel()

    def begin_motion(self) -> None:
        """Refuse with `busy` if a motion is in progress."""
        if self._motion is not None:
            raise RequestRefusedError(ErrorCode.BUSY, "another motion is in progress")

    def abort_motion(self) -> bool:
        """Stop the paced motion in progress; True if there was one."""
        if self._motion is None or self._motion.done():
            return False
        self._motion.set_result(None)
        return True
