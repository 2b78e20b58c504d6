"""Anonymous peers cannot stop a calibration or lock the operator out (issue 14).

Against a `controller-stub serve` subprocess on 127.0.0.1 whose motions take wall time:
40 unauthenticated sessions from another peer address (127.0.0.2) that say hello and send
heartbeats (and reconnect whenever the server closes them), plus one unauthenticated peer
(127.0.0.3) sending `abort` every 50 ms, while an
authenticated `hostpc calibrate --robot 127.0.0.1:PORT` runs as a subprocess and
`hostpc status` is asked again and again. The calibration completes with every pose
measured, every status answers, every anonymous abort is refused with `auth_required`.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import os
import sys
from pathlib import Path

import pytest

from hostpc.robots.simulator import SimulatedController
from protocol import messages as m
from protocol.connection import Connection
from protocol.message_base import Request
from protocol.session_states import ConnectionState, Role
from tests.integration.test_calibrate_sim import TOKEN, sim_scenario, truth_rig_file

ROOT = Path(__file__).resolve().parents[2]
N_HOLDERS = 40
N_POSES = 10
N_VERIFY = 3
HOLDERS_ADDRESS = "127.0.0.2"  # other hosts than the operator's, as on a cell network
ABORTER_ADDRESS = "127.0.0.3"  # (all loopback: Linux routes 127.0.0.0/8 to lo)


class Anonymous:
    """An unauthenticated peer (no token): hello, then whatever it is told to send."""

    def __init__(self, host: str, port: int, stop: asyncio.Event, source: str) -> None:
        self.host, self.port, self.source = host, port, source
        self.stop = stop
        self.replies: dict[str, int] = {}
        self.sessions = 0

    async def run(self, request: type[Request], every_s: float) -> None:
        """Until `stop`: connect, hello, send `request` every `every_s`; reconnect when
        closed. (Stops on the event, not only on cancellation: asyncio.wait_for of Python
        3.11 can swallow a cancellation that races with a completed read.)"""
        while not self.stop.is_set():
            with contextlib.suppress(ConnectionError, OSError, asyncio.IncompleteReadError):
                await self._session(request, every_s)
            await asyncio.sleep(0.05)

    async def _session(self, request: type[Request], every_s: float) -> None:
        reader, writer = await asyncio.open_connection(self.host, self.port,
                                                       local_addr=(self.source, 0))
        self.sessions += 1
        conn = Connection(Role.CLIENT, token=None)
        try:
            writer.write(conn.initiate())
            while not conn.closed and not self.stop.is_set():
                if conn.state is ConnectionState.AUTHENTICATING:
                    writer.write(conn.send(request(id=conn.next_id())))
                try:
                    async with asyncio.timeout(every_s):
                        data = await reader.read(1 << 16)
                except TimeoutError:
                    continue
                for event in conn.receive_data(data):
                    kind = getattr(event, "kind", None)
                    if kind is not None:
                        key = f"{kind}:{getattr(event, 'code', '')}"
                        self.replies[key] = self.replies.get(key, 0) + 1
        finally:
            writer.close()


async def hostpc(*args: str) -> tuple[int, str, str]:
    env = {**os.environ, "ZEROCAL_TOKEN": TOKEN, "PYTHONPATH": str(ROOT)}
    process = await asyncio.create_subprocess_exec(
        sys.executable, "-m", "hostpc.cli.main", *args, cwd=ROOT, env=env,
        stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE)
    try:
        async with asyncio.timeout(600):
            stdout, stderr = await process.communicate()
    except TimeoutError:
        process.kill()
        raise
    assert process.returncode is not None
    return process.returncode, stdout.decode(), stderr.decode()


@pytest.mark.slow
async def test_anonymous_peers_neither_stop_a_calibration_nor_lock_the_operator_out(
    tmp_path: Path,
) -> None:
    scenario = sim_scenario()
    scenario["motion"]["time_scale"] = 0.05  # motions take wall time: an abort could land
    rig = truth_rig_file(scenario, tmp_path / "rig.json")
    out = tmp_path / "run"
    with SimulatedController(scenario, tmp_path / "stub") as sim:
        host, port = sim.address.host, sim.address.port
        stop = asyncio.Event()
        holders = [Anonymous(host, port, stop, HOLDERS_ADDRESS) for _ in range(N_HOLDERS)]
        aborter = Anonymous(host, port, stop, ABORTER_ADDRESS)
        tasks = [asyncio.create_task(h.run(m.Heartbeat, 0.2)) for h in holders]
        tasks.append(asyncio.create_task(aborter.run(m.Abort, 0.05)))
        try:
            await asyncio.sleep(1.0)  # the anonymous sessions are in place
            calibrate = asyncio.create_task(hostpc(
                "calibrate", "--robot", f"{host}:{port}", "--rig", str(rig), "--known",
                "target", "--poses", str(N_POSES), "--verify-poses", str(N_VERIFY),
                "--no-report", "--json", "--out", str(out)))
            statuses: list[tuple[int, str, str]] = []
            while not calibrate.done():
                statuses.append(await hostpc("status", "--robot", f"{host}:{port}", "--json"))
            code, stdout, stderr = await calibrate
        finally:
            stop.set()
            for task in tasks:
                task.cancel()
            await asyncio.wait(tasks, timeout=10.0)
    assert code == 0, stderr
    document = json.loads(stdout)
    assert document["verify"]["n_measured"] == N_VERIFY
    dataset = json.loads((out / "dataset.json").read_text())
    assert len(dataset["samples"]) == N_POSES  # every fit pose measured, none skipped
    assert statuses and all(status == 0 for status, _, _ in statuses), statuses
    assert all(json.loads(text)["authenticated"] for _, text, _ in statuses)
    # the anonymous peers were there all along and got nothing but refusals
    assert sum(h.sessions for h in holders) >= N_HOLDERS
    assert aborter.replies.get("error:auth_required", 0) >= 10
    assert "aborted:" not in aborter.replies
    assert "aborted" not in (out / "journal.jsonl").read_text()
