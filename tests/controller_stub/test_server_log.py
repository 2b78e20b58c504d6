"""The stub's log after hostile input: one line per incident, never a traceback.

`controller-stub serve` runs as a subprocess (logging at INFO to a file); a corpus of
hostile input goes at it over loopback: deep nesting, wrong JSON types, huge numbers,
garbage bytes, oversized and truncated frames, wrong tokens, anonymous aborts. Then the log
is read: no "Traceback", no ERROR record. No hostpc imports.
"""

from __future__ import annotations

import os
import socket
import struct
import subprocess
import sys
from pathlib import Path

from protocol import messages as m
from protocol.connection import Connection
from protocol.framing import MAGIC, encode_frame
from protocol.session_states import Role
from tests.controller_stub.test_server_fuzz import (
    HUGE,
    WRONG_TYPES,
    BlockingClient,
    nested,
    read_until_closed,
    wrong_type_header,
)

ROOT = Path(__file__).resolve().parents[2]
TOKEN = "log-test-token"


def hostile_corpus() -> list[bytes]:
    frames = [
        encode_frame(f'{{"kind":"get_state","id":1,"x":{nested(d, o)}}}'.encode())
        for d in (40, 300, 1200, 20_000) for o in "[{"
    ]
    for kind in ("move_joints", "set_offsets", "guarded_move", "capture"):
        for field in ("id", "q.0", "offsets.0", "speed", "io_line", "view"):
            for value in WRONG_TYPES + HUGE:
                frames.append(encode_frame(wrong_type_header(kind, field, value).encode()))
    frames += [
        b"\x00" * 64,
        struct.pack(">2sHI", MAGIC, 0, 2**31),
        encode_frame(b"{not json"),
        encode_frame(b'{"kind":"get_state","id":1}')[:9],
        encode_frame(b'{"kind":"no_such_kind","id":1}'),
        encode_frame(m.Abort(id=3).model_dump_json().encode()),
    ]
    return frames


def attack(address: tuple[str, int], payload: bytes, prelude: str) -> None:
    if prelude == "none":
        sock = socket.create_connection(address, timeout=5)
    else:
        client = BlockingClient(address, token=TOKEN if prelude == "authenticated" else None)
        sock = client.sock
    try:
        try:
            sock.sendall(payload)
            sock.shutdown(socket.SHUT_WR)
        except OSError:
            pass
        sock.settimeout(5)
        read_until_closed(sock)
    finally:
        sock.close()


def wrong_token(address: tuple[str, int]) -> None:
    sock = socket.create_connection(address, timeout=5)
    conn = Connection(Role.CLIENT, token="not-the-token")
    try:
        sock.sendall(conn.initiate())
        while data := sock.recv(1 << 16):
            conn.receive_data(data)
            sock.sendall(conn.data_to_send())
    except OSError:
        pass
    finally:
        sock.close()


def test_hostile_input_leaves_no_traceback_in_the_log(tmp_path: Path) -> None:
    log_path = tmp_path / "stub.log"
    env = {**os.environ, "ZEROCAL_TOKEN": TOKEN, "PYTHONPATH": str(ROOT)}
    with open(log_path, "w") as log:
        stub = subprocess.Popen(
            [sys.executable, "-m", "controller_stub", "serve", "--port", "0",
             "--log-level", "INFO"],
            stdout=subprocess.PIPE, stderr=log, text=True, cwd=ROOT, env=env)
    try:
        assert stub.stdout is not None
        line = stub.stdout.readline()
        assert line.startswith("listening on "), log_path.read_text()
        host, _, port = line.split()[-1].rpartition(":")
        address = (host, int(port))
        corpus = hostile_corpus()
        for index, payload in enumerate(corpus):
            attack(address, payload, ("none", "hello", "authenticated")[index % 3])
        for _ in range(3):
            wrong_token(address)
        assert BlockingClient(address, token=TOKEN).heartbeat() >= 0.0  # still serving
    finally:
        stub.terminate()
        stub.wait(timeout=10)
        if stub.stdout is not None:
            stub.stdout.close()
    text = log_path.read_text()
    assert "authentication failed" in text and "nests deeper" in text  # it did log them
    assert "Traceback" not in text, text[-3000:]
    assert " ERROR " not in text, [ln for ln in text.splitlines() if " ERROR " in ln][:5]
