"""A UR controller that dies (SIGKILL) or freezes (SIGSTOP) mid-move: `hostpc calibrate --driver
ur` (a real subprocess, the real ur_rtde library) against `controller-stub serve --ur` at a
slow speed ends within a bound with the lost-controller line (exit code 3, "connection lost",
a resume hint). ur_rtde's getters repeat the last state they received (the move running, the
same RTDE timestamp), so the old driver polled forever, and its close blocked in stopScript
(Ctrl-C did not end it either)."""

from __future__ import annotations

import os
import signal
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest

rtde_receive = pytest.importorskip("rtde_receive")

from hostpc.robots.simulator import default_sim_scenario  # noqa: E402
from tests.integration.test_calibrate_sim import sim_scenario, truth_rig_file  # noqa: E402
from tests.integration.test_interrupt_motion import ENV, REPO  # noqa: E402
from tests.integration.ur_stub import calibrate_command, ur_stub_process  # noqa: E402

SPEED = 0.05
"""Speed fraction of the run: 0.157 rad/s, so a move lasts seconds."""
TIMEOUT_S = 2.0
"""hostpc's --timeout: how long the link may go without a new RTDE sample."""
EXIT_BOUND_S = 25.0
"""Bound on the time from the controller's death to hostpc's exit: the timeout, the close
steps (2 s each at most), start-up slack on 2 shared cores."""


@pytest.mark.parametrize("signum", [signal.SIGKILL, signal.SIGSTOP], ids=["killed", "frozen"])
def test_a_controller_lost_mid_move_ends_the_run(tmp_path: Path, signum: int) -> None:
    rig = truth_rig_file(sim_scenario(), tmp_path / "rig.json")
    out = tmp_path / "run"
    with ur_stub_process(tmp_path / "stub", base=default_sim_scenario(1.0)) as stub:
        receive = rtde_receive.RTDEReceiveInterface("127.0.0.1")
        command = calibrate_command(stub, rig, out, SPEED, "--timeout", str(TIMEOUT_S))
        process = subprocess.Popen(command, cwd=REPO, env=ENV, stdout=subprocess.DEVNULL,
                                   stderr=subprocess.PIPE, text=True)
        try:
            deadline = time.monotonic() + 60
            speed = 0.0
            while time.monotonic() < deadline and process.poll() is None and speed < 0.1:
                time.sleep(0.01)
                speed = float(np.max(np.abs(receive.getActualQd())))
            assert speed >= 0.1, "the arm is not moving"
            time.sleep(0.3)
            os.kill(stub.process.pid, signum)
            lost_at = time.monotonic()
            try:
                _, stderr = process.communicate(timeout=EXIT_BOUND_S)
            except subprocess.TimeoutExpired:
                pytest.fail(f"hostpc still runs {EXIT_BOUND_S:.0f} s after the controller "
                            "was lost")
            took = time.monotonic() - lost_at
        finally:
            if signum == signal.SIGSTOP:
                os.kill(stub.process.pid, signal.SIGCONT)
            if process.poll() is None:
                process.kill()
                process.wait()
            try:
                receive.disconnect()
            except RuntimeError:
                pass
    assert process.returncode == 3, stderr
    last = stderr.strip().splitlines()[-1]
    assert "connection lost" in last, stderr
    assert f"continue with: hostpc calibrate --resume {out}" in last, stderr
    assert took >= TIMEOUT_S - 0.5, took  # not before the link's timeout
