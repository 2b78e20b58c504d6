"""Helpers of the integration tests that run `hostpc calibrate` in-process against a
SimulatedController (tests/integration/test_calibrate_kill_resume.py, _refusals.py): the
robot options that point the CLI at the simulator, and one call that resumes a run folder
on it."""

from __future__ import annotations

from pathlib import Path

import pytest

from hostpc.robots.simulator import SimulatedController
from tests.integration.test_calibrate_sim import TOKEN, run_cli


def robot_args(sim: SimulatedController, token: str = TOKEN) -> tuple[str, ...]:
    """``--robot HOST:PORT --token TOKEN`` of the running simulator."""
    return ("--robot", f"{sim.address.host}:{sim.address.port}", "--token", token)


def resume_on(capsys: pytest.CaptureFixture[str], sim: SimulatedController, run: Path,
              *extra: str) -> tuple[int, str, str]:
    """`hostpc calibrate --resume RUN` against ``sim`` -> (exit code, stdout, stderr)."""
    return run_cli(capsys, "calibrate", "--resume", str(run), *robot_args(sim), *extra)
