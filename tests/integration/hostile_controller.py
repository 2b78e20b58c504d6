"""Controllers that misreport a push, on 127.0.0.1 port 0, each in a thread of its own.

`HostileController` speaks docs/protocol.md itself (raw frames, the public token, a correct
handshake) and misbehaves in the one way its `mode` names; `ClampingProxy` sits between
hostpc and a real controller (the stub) and clamps every `set_offsets` it forwards, so the
controller stores, and honestly reports, other offsets than hostpc asked for (after the
handshake nothing is authenticated: docs/protocol.md "Security model").
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import threading
from collections.abc import Awaitable, Callable
from typing import Any

from protocol.auth import new_nonce, server_proof
from protocol.framing import FrameDecoder, encode_frame

TOKEN = "zerocal-sim"
N_JOINTS = 6
MODES = ("ok", "lie_prev", "clamp", "ignore", "slow_set", "drop_set_once", "wrongid",
         "clamp_no_readback")
"""ok: honest; lie_prev: stores the offsets but names 0.5 rad as the ones it replaced, and
knows no rollback id; clamp: stores them clamped to +-CLAMP_RAD and says so in its reply;
ignore: stores nothing, replies as if it had; slow_set: never answers set_offsets;
drop_set_once: stores the first set_offsets, then closes the connection without a reply;
wrongid: answers get_state and get_offsets with a reply_to 100 too high;
clamp_no_readback: as clamp, and never answers the first get_offsets after its first
set_offsets (the push's read-back); it undoes a write by its rollback id."""
CLAMP_RAD = 0.001

Handler = Callable[[asyncio.StreamReader, asyncio.StreamWriter], Awaitable[None]]


async def read_message(reader: asyncio.StreamReader, decoder: FrameDecoder) -> Any:
    """The next frame's JSON header, or None at the end of the stream."""
    while True:
        frame = decoder.next_frame()
        if frame is not None:
            return json.loads(bytes(frame.header))
        data = await reader.read(1 << 16)
        if not data:
            return None
        decoder.feed(data)


def frame(message: dict[str, Any]) -> bytes:
    return encode_frame(json.dumps(message).encode())


class ThreadServer:
    """An asyncio TCP server on 127.0.0.1 port 0 with its own loop in a daemon thread."""

    def __init__(self, handler: Handler) -> None:
        self._handler = handler
        self.loop = asyncio.new_event_loop()
        self._thread = threading.Thread(target=self.loop.run_forever, daemon=True)
        self._server: asyncio.Server | None = None
        self._tasks: set[asyncio.Task[Any]] = set()
        self.port = 0

    async def _serve(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        task = asyncio.current_task()
        assert task is not None
        self._tasks.add(task)
        try:
            with contextlib.suppress(ConnectionError, asyncio.IncompleteReadError,
                                     asyncio.CancelledError):  # CancelledError: __exit__
                await self._handler(reader, writer)
        finally:
            writer.close()
            self._tasks.discard(task)

    def __enter__(self) -> ThreadServer:
        self._thread.start()
        self._server = asyncio.run_coroutine_threadsafe(
            asyncio.start_server(self._serve, "127.0.0.1", 0), self.loop).result(10)
        self.port = self._server.sockets[0].getsockname()[1]
        return self

    @property
    def address(self) -> str:
        return f"127.0.0.1:{self.port}"

    def __exit__(self, *exc: object) -> None:
        async def stop() -> None:
            assert self._server is not None
            self._server.close()
            for task in list(self._tasks):
                task.cancel()
            await asyncio.sleep(0)

        asyncio.run_coroutine_threadsafe(stop(), self.loop).result(10)
        self.loop.call_soon_threadsafe(self.loop.stop)
        self._thread.join(10)
        self.loop.close()


class HostileController(ThreadServer):
    """A 6-joint "ur5e" controller that misreports offset writes as `mode` says (MODES).
    `offsets` (rad) is what it holds; `requests` the kinds it was sent, in order."""

    def __init__(self, mode: str, offsets: list[float] | None = None) -> None:
        assert mode in MODES, mode
        super().__init__(self._session)
        self.mode = mode
        self.offsets = list(offsets or [0.0] * N_JOINTS)
        self.replaced: list[list[float]] = []  # per write (rollback id rb-k): the offsets before
        self.requests: list[str] = []
        self._dropped = False

    async def _session(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        decoder = FrameDecoder()
        server_nonce = client_nonce = ""
        while (message := await read_message(reader, decoder)) is not None:
            kind, i = message.get("kind"), message.get("id")
            self.requests.append(str(kind))
            if kind == "hello":
                client_nonce, server_nonce = message["client_nonce"], new_nonce()
                reply = {"kind": "hello_reply", "reply_to": i, "protocol_version": 1,
                         "server_name": "hostile", "robot_name": "ur5e",
                         "server_nonce": server_nonce}
            elif kind == "auth":
                reply = {"kind": "auth_reply", "reply_to": i,
                         "server_proof": server_proof(TOKEN, server_nonce, client_nonce)}
            elif kind == "get_state":
                reply = {"kind": "state", "reply_to": i, "robot_name": "ur5e",
                         "n_joints": N_JOINTS, "mode": "idle", "time": 1.0,
                         "q": [0.0] * N_JOINTS, "zero_offsets": self.offsets,
                         "q_min": [-6.2] * N_JOINTS, "q_max": [6.2] * N_JOINTS,
                         "digital_inputs": [False] * 8, "digital_outputs": [False] * 8,
                         "camera": {}, "authenticated": True}
            elif kind == "get_offsets":
                if self.mode == "clamp_no_readback" and len(self.replaced) == 1 \
                        and not self._dropped:
                    self._dropped = True
                    await asyncio.sleep(3600)
                reply = {"kind": "offsets", "reply_to": i, "offsets": self.offsets}
            elif kind == "set_offsets":
                answer = await self._set_offsets(message["offsets"], i)
                if answer is None:
                    return  # the connection closes without a reply
                reply = answer
            elif kind == "rollback_offsets":
                reply = self._rollback(message["rollback_id"], i)
            else:
                reply = {"kind": "error", "reply_to": i, "code": "refused", "message": "no",
                         "reason": "unsupported"}
            if self.mode == "wrongid" and kind in ("get_state", "get_offsets"):
                reply["reply_to"] = i + 100
            writer.write(frame(reply))
            await writer.drain()

    async def _set_offsets(self, requested: list[float], i: int) -> dict[str, Any] | None:
        previous = list(self.offsets)
        reported = previous
        if self.mode in ("clamp", "clamp_no_readback"):
            self.offsets = [max(-CLAMP_RAD, min(CLAMP_RAD, v)) for v in requested]
        elif self.mode == "lie_prev":
            self.offsets, reported = list(requested), [0.5] * N_JOINTS
        elif self.mode == "slow_set":
            await asyncio.sleep(3600)
        elif self.mode == "drop_set_once" and not self._dropped:
            self._dropped = True
            self.offsets = list(requested)
            return None
        elif self.mode != "ignore":
            self.offsets = list(requested)
        self.replaced.append(previous)
        return {"kind": "offsets_set", "reply_to": i, "offsets": self.offsets,
                "previous": reported, "rollback_id": f"rb-{len(self.replaced)}"}

    def _rollback(self, rollback_id: str, i: int) -> dict[str, Any]:
        k = int(rollback_id.removeprefix("rb-")) if rollback_id.startswith("rb-") else 0
        if self.mode == "lie_prev" or not 1 <= k <= len(self.replaced):
            return {"kind": "error", "reply_to": i, "code": "unknown_rollback",
                    "message": "restarted", "reason": None}
        if self.mode not in ("clamp", "ignore"):  # those answer but undo nothing
            self.offsets = list(self.replaced[k - 1])
        return {"kind": "offsets_rolled_back", "reply_to": i, "offsets": self.offsets,
                "replaced": self.offsets}


class ClampingProxy(ThreadServer):
    """Forwards every connection to `upstream` (host, port), clamping the offsets of each
    `set_offsets` request to +-CLAMP_RAD on the way: the controller behind it stores the
    clamped offsets and reports them truthfully. With `drop_read_back`, it clamps nothing
    and instead swallows the first `get_offsets` after the first `set_offsets` (the push's
    read-back never reaches the controller, so it never answers)."""

    def __init__(self, upstream: tuple[str, int], drop_read_back: bool = False) -> None:
        super().__init__(self._session)
        self.upstream = upstream
        self.clamped = 0
        self.drop_read_back = drop_read_back
        self.dropped = 0
        self._written = False

    async def _session(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        up_reader, up_writer = await asyncio.open_connection(*self.upstream)
        back = asyncio.create_task(self._pipe(up_reader, writer))
        try:
            decoder = FrameDecoder()
            while (message := await read_message(reader, decoder)) is not None:
                if message.get("kind") == "set_offsets" and self.drop_read_back:
                    self._written = True
                elif message.get("kind") == "set_offsets":
                    message["offsets"] = [max(-CLAMP_RAD, min(CLAMP_RAD, v))
                                          for v in message["offsets"]]
                    self.clamped += 1
                elif message.get("kind") == "get_offsets" and self._written \
                        and not self.dropped:
                    self.dropped += 1
                    continue  # never forwarded: the controller never answers it
                up_writer.write(frame(message))
                await up_writer.drain()
        finally:
            back.cancel()
            up_writer.close()

    @staticmethod
    async def _pipe(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        while data := await reader.read(1 << 16):
            writer.write(data)
            await writer.drain()
        writer.close()
