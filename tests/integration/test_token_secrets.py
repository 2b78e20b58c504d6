"""Tokens stay secret: never in a run folder, never in zerocal's own process arguments;
read from the environment or a private file; a warning when given on the command line."""

from __future__ import annotations

import asyncio
import json
import socket
from pathlib import Path

import pytest

from hostpc.cli.main import main
from hostpc.errors import InputError
from hostpc.robots.connect import parse_robot, read_token_file
from hostpc.robots.simulator import SimulatedController
from hostpc.robots.zerocal import ZerocalAdapter

SECRET = "cell-secret-4f1c9"


def test_the_simulator_gets_its_token_by_environment_not_arguments(tmp_path: Path) -> None:
    scenario = {"robot": "ur5e", "camera": {"image_width": 64, "image_height": 48},
                "server": {"token": SECRET}}
    with SimulatedController(scenario, tmp_path / "sim") as sim:
        assert sim.process is not None
        cmdline = Path(f"/proc/{sim.process.pid}/cmdline").read_bytes()
        assert SECRET.encode() not in cmdline
        written = sim.scenario_path.read_text()
        assert SECRET not in written and json.loads(written)["server"] == {}

        async def authenticated() -> bool:
            robot = await ZerocalAdapter.connect(sim.address.host, sim.address.port,
                                                 token=SECRET, timeout=5.0)
            try:
                return bool(robot.client.authenticated)
            finally:
                await robot.close()

        assert asyncio.run(authenticated())
    for path in (tmp_path / "sim").rglob("*"):
        assert SECRET not in path.read_text(errors="replace"), path


def closed_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


def test_hostpc_token_options(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    robot = f"127.0.0.1:{closed_port()}"
    token_file = tmp_path / "token"
    token_file.write_text(SECRET + "\n")
    token_file.chmod(0o644)
    assert main(["status", "--robot", robot, "--token-file", str(token_file)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "readable by others (mode 0644); chmod 600" in err
    token_file.chmod(0o600)
    assert read_token_file(token_file) == SECRET
    assert main(["status", "--robot", robot, "--token-file", str(token_file),
                 "--timeout", "1"]) == 3  # read, then the (closed) controller is unreachable
    assert "warning" not in capsys.readouterr().err
    assert main(["status", "--robot", robot, "--token", SECRET, "--timeout", "1"]) == 3
    err = capsys.readouterr().err
    assert "warning: --token is visible" in err and SECRET not in err
    assert main(["status", "--robot", robot, "--token", ""]) == 2
    assert "--token: the token is empty" in capsys.readouterr().err
    assert main(["rollback", "--robot", robot, "--token", "a", "--token-file",
                 str(token_file), "--id", "rb-1"]) == 2
    assert "give one of them" in capsys.readouterr().err


@pytest.mark.parametrize("text", ["127.0.0.1:", "[::1]:", "robot:"])
def test_a_host_with_a_colon_but_no_port_is_an_error(text: str) -> None:
    with pytest.raises(InputError, match="no port after ':'"):
        parse_robot(text)
    assert parse_robot("[::1]").port == parse_robot("robot").port  # no colon: the default
