"""Run `controller-stub serve --ur` as a subprocess for the UR tests (import as
tests.integration.ur_stub).

The UR ports are fixed (RTDE 30004, dashboard 29999, script 30003), so only one UR stub may
run at a time: the tests use one module-scoped stub per test module, and `ur_stub_process`
refuses to start when a port is taken. The stub must be a separate process: ur_rtde's
constructors hold the GIL, so an in-process stub would deadlock. The subprocess is always
terminated (then killed) on exit; its stderr goes to a file, never a pipe that could fill.
"""

from __future__ import annotations

import contextlib
import queue
import socket
import subprocess
import sys
import threading
from collections.abc import AsyncIterator, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import yaml

if TYPE_CHECKING:
    from hostpc.robots.ur import UrAdapter

UR_PORTS = (30004, 29999, 30003)
TOKEN = "test-token"
START_TIMEOUT_S = 30.0

SCENARIO: dict[str, Any] = {
    "seed": 7,
    "robot": "ur5e",
    "camera": {
        "image_width": 320,
        "image_height": 256,
        "fx": 350.0,
        "fy": 350.0,
        "cx": 160.3,
        "cy": 127.7,
    },
    "server": {"token": TOKEN},
}


@dataclass
class UrStub:
    """A running UR stub: host, zerocal port, the process, the truth file, its stderr log."""

    host: str
    port: int
    process: subprocess.Popen[str]
    truth_out: Path
    log: Path


def port_in_use(port: int, host: str = "127.0.0.1") -> bool:
    """True if something accepts connections on host:port."""
    with socket.socket() as probe:
        probe.settimeout(0.5)
        return probe.connect_ex((host, port)) == 0


def merge(base: dict[str, Any], overrides: dict[str, Any]) -> dict[str, Any]:
    """Deep-merge `overrides` into a copy of `base`."""
    merged = dict(base)
    for key, value in overrides.items():
        if isinstance(value, dict) and isinstance(merged.get(key), dict):
            merged[key] = merge(merged[key], value)
        else:
            merged[key] = value
    return merged


@contextlib.contextmanager
def ur_stub_process(
    directory: Path, overrides: dict[str, Any] | None = None, base: dict[str, Any] | None = None
) -> Iterator[UrStub]:
    """Start `controller-stub serve --ur --port 0` with `base` (default SCENARIO) + overrides;
    stop it after."""
    busy = [port for port in UR_PORTS if port_in_use(port)]
    if busy:
        raise RuntimeError(f"UR ports {busy} are in use: another UR stub is running")
    directory.mkdir(parents=True, exist_ok=True)
    scenario = directory / "scenario.yaml"
    scenario.write_text(yaml.safe_dump(merge(base or SCENARIO, overrides or {})))
    truth = directory / "truth.json"
    log = directory / "stub.log"
    command = [
        sys.executable, "-m", "controller_stub", "serve", "--ur", "--port", "0",
        "--scenario", str(scenario), "--truth-out", str(truth), "--log-level", "INFO",
    ]
    with log.open("w") as log_file:
        process = subprocess.Popen(
            command, stdout=subprocess.PIPE, stderr=log_file, text=True
        )
    try:
        lines: queue.Queue[str] = queue.Queue()

        def pump() -> None:
            assert process.stdout is not None
            for line in process.stdout:
                lines.put(line)

        threading.Thread(target=pump, daemon=True).start()
        while True:
            try:
                line = lines.get(timeout=START_TIMEOUT_S)
            except queue.Empty:
                raise RuntimeError(f"UR stub did not start: {log.read_text()[-2000:]}") from None
            if line.startswith("listening on "):
                host, _, port = line.split()[-1].rpartition(":")
                break
        yield UrStub(host, int(port), process, truth, log)
    finally:
        process.terminate()
        try:
            process.wait(timeout=10)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait(timeout=10)


@contextlib.asynccontextmanager
async def ur_adapter(stub: UrStub) -> AsyncIterator[UrAdapter]:
    """hostpc's UR adapter (ur_rtde) on `stub`, 10 s timeout; closed after."""
    from hostpc.robots.ur import connect_ur  # needs ur_rtde: the tests skip without it

    robot = await connect_ur("127.0.0.1", stub.host, stub.port, TOKEN, timeout=10.0)
    try:
        yield robot
    finally:
        await robot.close()


def dashboard(command: str, host: str = "127.0.0.1") -> str:
    """Send one dashboard command (raw socket); returns the reply line."""
    with socket.create_connection((host, 29999), timeout=5) as sock:
        reader = sock.makefile("r")
        reader.readline()
        sock.sendall(f"{command}\n".encode())
        return reader.readline().strip()


def calibrate_command(stub: UrStub, rig: Path, out: Path, speed: float, *extra: str
                      ) -> list[str]:
    """`hostpc calibrate --driver ur` against `stub`: 8 poses of the known target, no
    verification, no report, at speed fraction `speed`, then `extra` arguments."""
    return [sys.executable, "-m", "hostpc.cli.main", "calibrate",
            "--robot", f"{stub.host}:{stub.port}", "--driver", "ur", "--rig", str(rig),
            "--known", "target", "--poses", "8", "--verify-poses", "0", "--cv-folds", "0",
            "--no-report", "--speed", str(speed), *extra, "--out", str(out)]
