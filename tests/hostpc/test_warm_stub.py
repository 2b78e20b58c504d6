"""The simulator process started before hostpc's imports (hostpc/robots/warm_stub.py,
controller_stub/warm.py): `SimulatedController` takes it and it serves exactly as a fresh
stub with the token it was handed; one nobody takes ends; a dead one is replaced by a fresh
process. Real processes and sockets; the stub listens on port 0."""

from __future__ import annotations

import asyncio
from collections.abc import Iterator
from pathlib import Path

import pytest

from hostpc.robots import warm_stub
from hostpc.robots.connect import open_robot
from hostpc.robots.simulator import SimulatedController, default_sim_scenario


@pytest.fixture(autouse=True)
def _no_warm_process_left() -> Iterator[None]:
    yield
    warm_stub.discard()


def _offsets_through(sim: SimulatedController, token: str) -> list[float]:
    async def read() -> list[float]:
        robot = await open_robot(sim.address, token=token, timeout=10.0)
        try:
            return [float(v) for v in await robot.get_offsets()]
        finally:
            await robot.close()

    return asyncio.run(read())


def test_the_simulator_takes_the_warm_process_and_serves_with_its_token(tmp_path: Path) -> None:
    warm_stub.prestart()
    warm = warm_stub._warm
    assert warm is not None
    with SimulatedController(default_sim_scenario(), tmp_path, token="warm-secret") as sim:
        assert sim.process is warm  # no second process
        assert len(_offsets_through(sim, "warm-secret")) == 6
        with pytest.raises(Exception, match="(?i)auth|token"):
            _offsets_through(sim, "another-token")
        assert "camera" in sim.truth()
    assert warm.returncode is not None  # stopped with the simulator
    log = (tmp_path / "stub.log").read_text()
    assert log.startswith("listening on 127.0.0.1:")
    assert "warm-secret" not in (tmp_path / "scenario.json").read_text()


def test_a_warm_process_nobody_takes_ends(tmp_path: Path) -> None:
    warm_stub.prestart()
    warm = warm_stub._warm
    assert warm is not None
    warm_stub.discard()
    assert warm.returncode is not None
    assert warm_stub.take() is None


def test_a_dead_warm_process_is_replaced_by_a_fresh_one(tmp_path: Path) -> None:
    warm_stub.prestart()
    warm = warm_stub._warm
    assert warm is not None
    warm.kill()
    warm.wait()
    with SimulatedController(default_sim_scenario(), tmp_path, token="t0k3n") as sim:
        assert sim.process is not None and sim.process is not warm
        assert len(_offsets_through(sim, "t0k3n")) == 6


@pytest.mark.parametrize(("words", "wanted"), [
    (["calibrate", "--robot", "sim"], True),
    (["calibrate", "--out", "x", "--robot=sim"], True),
    (["calibrate", "--robot", "sim", "--check"], False),
    (["calibrate", "--robot", "sim", "--help"], False),
    (["calibrate", "--robot", "10.0.0.2"], False),
    (["calibrate", "--resume", "run"], False),
])
def test_which_command_lines_start_a_simulator(words: list[str], wanted: bool) -> None:
    assert warm_stub.wants_simulator(words[0], words) is wanted


def test_waiting_for_a_process_to_end_returns_its_exit_code_or_times_out() -> None:
    import subprocess
    import sys

    process = subprocess.Popen([sys.executable, "-c", "import sys; sys.stdin.read()"],
                               stdin=subprocess.PIPE, text=True)
    with pytest.raises(subprocess.TimeoutExpired):
        warm_stub.wait_for_exit(process, timeout=0.2)
    assert process.returncode is None
    assert process.stdin is not None
    process.stdin.close()  # it ends
    assert warm_stub.wait_for_exit(process, timeout=30) == 0
    assert warm_stub.wait_for_exit(process, timeout=1) == 0  # reaped already
