"""Ctrl-C during a move stops the robot: `hostpc calibrate` (a real subprocess) against a
real stub at time_scale 1 gets SIGINT while the stub reports "moving"; the client sends the
controller's `abort` before the link closes, so the stub stands still short of the target
(not "moving", its q unchanged afterwards), and the interrupt line says what was done."""

from __future__ import annotations

import asyncio
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from hostpc.robots.simulator import SimulatedController, default_sim_scenario
from hostpc.transport import ControllerClient, ControllerState
from tests.integration.test_calibrate_sim import TOKEN, sim_scenario, truth_rig_file

REPO = Path(__file__).resolve().parents[2]


def _state(host: str, port: int) -> ControllerState:
    async def read() -> ControllerState:
        async with ControllerClient.connect(host, port, token=TOKEN, timeout=5.0) as client:
            return await client.state()
    return asyncio.run(read())


def test_ctrl_c_during_a_move_aborts_it(tmp_path: Path) -> None:
    rig = truth_rig_file(sim_scenario(), tmp_path / "rig.json")
    out = tmp_path / "run"
    with SimulatedController(default_sim_scenario(time_scale=1.0), tmp_path / "stub") as sim:
        host, port = sim.address.host, sim.address.port
        command = [sys.executable, "-m", "hostpc.cli.main", "calibrate",
                   "--robot", f"{host}:{port}", "--rig", str(rig),
                   "--known", "target", "--poses", "8", "--verify-poses", "0",
                   "--cv-folds", "0", "--no-report", "--speed", "0.05", "--out", str(out)]
        env = {**os.environ, "PYTHONPATH": str(REPO), "ZEROCAL_TOKEN": TOKEN}
        process = subprocess.Popen(command, cwd=REPO, env=env, stdout=subprocess.PIPE,
                                   stderr=subprocess.PIPE, text=True)
        try:
            deadline = time.monotonic() + 60
            while time.monotonic() < deadline and process.poll() is None:
                if _state(host, port).mode == "moving":
                    break
                time.sleep(0.05)
            time.sleep(0.3)  # well inside the move: at speed 0.05 it takes seconds
            assert _state(host, port).mode == "moving"
            process.send_signal(signal.SIGINT)
            _, stderr = process.communicate(timeout=30)
        finally:
            if process.poll() is None:
                process.kill()
                process.wait()
        assert process.returncode == 130, stderr
        after = _state(host, port)
        time.sleep(0.5)
        later = _state(host, port)
        assert after.mode == later.mode == "idle", stderr
        np.testing.assert_array_equal(later.q, after.q)  # stopped, not finishing the move
        assert stderr.strip().splitlines()[-1] == (
            "hostpc calibrate: interrupted (move_joints interrupted: abort sent: motion "
            f"stopped): continue with hostpc calibrate --resume {out}")
