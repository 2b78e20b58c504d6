"""`controller-stub serve` and `hostpc status` as subprocesses on 127.0.0.1."""

from __future__ import annotations

import json
import os
import re
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.integration.conftest import BASE_SCENARIO, TOKEN

LISTENING = re.compile(r"^listening on (?P<host>[0-9.]+):(?P<port>\d+)$")


@pytest.fixture(scope="module")
def served(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[str, int, Path]]:
    """A `controller-stub serve --port 0` subprocess; yields (host, port, truth file)."""
    directory = tmp_path_factory.mktemp("stub")
    scenario = directory / "scenario.json"
    scenario.write_text(json.dumps(BASE_SCENARIO))
    truth = directory / "truth.json"
    command = [
        sys.executable, "-m", "controller_stub", "serve",
        "--scenario", str(scenario), "--port", "0", "--truth-out", str(truth),
    ]  # fmt: skip
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert process.stdout is not None
        line = process.stdout.readline().strip()  # blocks until ready (or the process dies)
        match = LISTENING.match(line)
        assert match, f"unexpected first line {line!r}; stderr: {process.stderr.read()}"
        yield match["host"], int(match["port"]), truth
    finally:
        process.terminate()
        process.wait(timeout=10)


def hostpc(*args: str, env: dict[str, str] | None = None) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "hostpc.cli.main", *args],
        capture_output=True,
        text=True,
        timeout=60,
        env={**os.environ, **(env or {})},
    )


def test_status_prints_state_in_degrees(served: tuple[str, int, Path]) -> None:
    host, port, truth = served
    result = hostpc("status", "--robot", f"{host}:{port}", "--token", TOKEN)
    assert result.returncode == 0, result.stderr
    assert "robot ur5e" in result.stdout and "session authenticated" in result.stdout
    assert re.search(r"^J2\s+-90\.0000\s+0\.00000\s+-360\.00\s+360\.00$", result.stdout, re.M)
    assert "digital inputs : 0 0 0 0 0 0 0 0" in result.stdout
    assert json.loads(truth.read_text())["robot"] == "ur5e"


def test_status_json_with_token_from_environment(served: tuple[str, int, Path]) -> None:
    host, port, _ = served
    result = hostpc("status", "--robot", f"{host}:{port}", "--json", env={"ZEROCAL_TOKEN": TOKEN})
    assert result.returncode == 0, result.stderr
    state = json.loads(result.stdout)
    assert state["robot"] == "ur5e" and state["authenticated"] is True
    assert state["joints_deg"][1] == pytest.approx(-90.0)
    assert len(state["zero_offsets_deg"]) == 6 and len(state["q_max_deg"]) == 6


def test_status_wrong_token_is_one_line_exit_4(served: tuple[str, int, Path]) -> None:
    host, port, _ = served
    result = hostpc("status", "--robot", f"{host}:{port}", env={"ZEROCAL_TOKEN": "nope"})
    assert result.returncode == 4
    assert result.stderr.count("\n") == 1 and "auth_failed" in result.stderr


def test_status_unreachable_is_one_line_exit_3() -> None:
    with socket.socket() as probe:  # a port that was free a moment ago
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    started = time.monotonic()
    result = hostpc("status", "--robot", f"127.0.0.1:{port}", "--timeout", "2")
    assert result.returncode == 3
    assert result.stdout == ""
    assert result.stderr.count("\n") == 1 and "Traceback" not in result.stderr
    assert result.stderr.startswith("hostpc status: error: cannot reach controller")
    assert time.monotonic() - started < 30


def test_status_rejects_a_malformed_address() -> None:
    result = hostpc("status", "--robot", "127.0.0.1:notaport")
    assert result.returncode == 2 and "notaport" in result.stderr


def test_status_against_a_silent_server_is_one_line_exit_3() -> None:
    """A port that accepts but never answers: a handshake timeout, and nothing else on
    stderr (no "Future exception was never retrieved")."""
    with socket.socket() as silent:
        silent.bind(("127.0.0.1", 0))
        silent.listen(4)  # the kernel accepts; nobody ever reads or writes
        port = silent.getsockname()[1]
        result = hostpc("status", "--robot", f"127.0.0.1:{port}", "--timeout", "1")
    assert result.returncode == 3
    assert result.stdout == ""
    assert result.stderr.count("\n") == 1, result.stderr
    assert "did not complete the handshake" in result.stderr
