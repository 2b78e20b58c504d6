"""Ctrl-C during a move stops the robot: `hostpc calibrate` (a real subprocess) against a
real stub at time_scale 1 gets SIGINT while the stub reports "moving"; the client sends the
controller's `abort` before the link closes, so the stub stands still short of the target
(not "moving", its q unchanged afterwards), and the interrupt line says what was done."""

from __future__ import annotations

import asyncio
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from hostpc.robots.simulator import SimulatedController, default_sim_scenario
from hostpc.transport import ControllerClient, ControllerState
from tests.integration.test_calibrate_sim import TOKEN, sim_scenario, truth_rig_file

REPO = Path(__file__).resolve().parents[2]


def _state(host: str, port: int) -> ControllerState:
    async def read() -> ControllerState:
        async with ControllerClient.connect(host, port, token=TOKEN, timeout=5.0) as client:
            return await client.state()
    return asyncio.run(read())


ENV = {**os.environ, "PYTHONPATH": str(REPO), "ZEROCAL_TOKEN": TOKEN}


def _ignore_sigint() -> None:
    """In the child before exec: SIGINT ignored, as a shell starts a background command
    (`hostpc calibrate ... &` in a script) and as every child of such a process inherits."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _interrupt_a_move(host: str, port: int, rig: Path, out: Path, poses_first: int,
                      sigint_ignored: bool = False) -> tuple[int, str]:
    """Run `hostpc calibrate` against the stub; once
    `poses_first` fit poses are journaled, SIGINT it 0.1 s into a move -> (exit code, stderr)."""
    command = [sys.executable, "-m", "hostpc.cli.main", "calibrate",
               "--robot", f"{host}:{port}", "--rig", str(rig),
               "--known", "target", "--poses", "8", "--verify-poses", "0",
               "--cv-folds", "0", "--no-report", "--speed", "0.05", "--out", str(out)]
    process = subprocess.Popen(command, cwd=REPO, env=ENV, stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True,
                               preexec_fn=_ignore_sigint if sigint_ignored else None)
    journal = out / "journal.jsonl"
    try:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and process.poll() is None:
            lines = journal.read_text().replace(" ", "").splitlines() if journal.is_file() else []
            measured = sum('"event":"robot_time","phase":"measure"' in line for line in lines)
            if measured >= poses_first and _state(host, port).mode == "moving":
                break
            time.sleep(0.05)
        time.sleep(0.1)  # inside the move: at speed 0.05 it takes seconds of robot time
        assert _state(host, port).mode == "moving"
        process.send_signal(signal.SIGINT)
        _, stderr = process.communicate(timeout=30)
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
    return process.returncode, stderr


@pytest.mark.parametrize("sigint_ignored", [False, True], ids=["foreground", "inherited-ignored"])
def test_ctrl_c_during_a_move_aborts_it(tmp_path: Path, sigint_ignored: bool) -> None:
    """Also when the process inherited SIGINT ignored (started in the background by a
    script, or by a station that was): the command takes SIGINT back, so Ctrl-C and the
    station's stop still stop it (before, it ran on for the 30 s and pushed)."""
    rig = truth_rig_file(sim_scenario(), tmp_path / "rig.json")
    out = tmp_path / "run"
    with SimulatedController(default_sim_scenario(time_scale=1.0), tmp_path / "stub") as sim:
        host, port = sim.address.host, sim.address.port
        code, stderr = _interrupt_a_move(host, port, rig, out, 0, sigint_ignored)
        assert code == 130, stderr
        after = _state(host, port)
        time.sleep(0.5)
        later = _state(host, port)
        assert after.mode == later.mode == "idle", stderr
        np.testing.assert_array_equal(later.q, after.q)  # stopped, not finishing the move
        assert stderr.strip().splitlines()[-1] == (
            "hostpc calibrate: interrupted (move_joints interrupted: abort sent: motion "
            f"stopped): continue with hostpc calibrate --resume {out}")


@pytest.mark.slow
def test_a_resume_on_a_controller_that_ran_on_counts_all_its_robot_time(tmp_path: Path
                                                                       ) -> None:
    """Interrupted in the move to the third pose, resumed against the same controller (its
    clock ran on): the run's robot time is all the controller clock advanced, the move and
    settling into the interrupted pose included."""
    rig = truth_rig_file(sim_scenario(), tmp_path / "rig.json")
    out = tmp_path / "run"
    with SimulatedController(default_sim_scenario(time_scale=0.5), tmp_path / "stub") as sim:
        host, port = sim.address.host, sim.address.port
        start = _state(host, port).time
        code, stderr = _interrupt_a_move(host, port, rig, out, 2)
        assert code == 130, stderr
        done = subprocess.run([sys.executable, "-m", "hostpc.cli.main", "calibrate",
                               "--resume", str(out)], cwd=REPO, env=ENV,
                              capture_output=True, text=True, timeout=120)
        assert done.returncode == 0, done.stderr[-2000:]
        spent = _state(host, port).time - start
    robot_time = json.loads((out / "result.json").read_text())["robot_time_s"]
    assert robot_time["clock"] == "controller"
    assert robot_time["total"] == pytest.approx(spent, rel=1e-9), (robot_time, spent)


def test_a_sim_controller_killed_after_the_push_names_the_offsets_it_held(tmp_path: Path
                                                                         ) -> None:
    """`hostpc calibrate --robot sim` whose simulated controller (its child process) is
    killed (SIGKILL) once the push is journaled, during verification: exit 3, and the line
    says the controller held the pushed offsets, not verified, and the resume that pushes
    them again, which passes (before, only "continue with: ... --resume", which reports
    "push lost")."""
    out = tmp_path / "run"
    command = [sys.executable, "-m", "hostpc.cli.main", "calibrate", "--robot", "sim",
               "--time-scale", "0.3", "--cv-folds", "0", "--no-report", "--out", str(out)]
    process = subprocess.Popen(command, cwd=REPO, env=ENV, stdout=subprocess.DEVNULL,
                               stderr=subprocess.PIPE, text=True)
    journal = out / "journal.jsonl"
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and process.poll() is None and not (
                journal.is_file() and '"event":"push"' in journal.read_text().replace(" ", "")):
            time.sleep(0.05)
        children = Path(f"/proc/{process.pid}/task/{process.pid}/children").read_text().split()
        assert children, "no simulated controller"
        for child in children:
            os.kill(int(child), signal.SIGKILL)
        _, stderr = process.communicate(timeout=60)
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
    push = json.loads((out / "push.json").read_text())
    assert process.returncode == 3, stderr
    assert stderr.strip().splitlines()[-1].endswith(
        f"the simulated controller held the offsets pushed at {push['time']} (rollback id "
        f"{push['rollback_id']}), NOT verified, and ended with the run; a resume restarts it "
        f"with its initial offsets: hostpc calibrate --resume {out} --push"), stderr
    done = subprocess.run([sys.executable, "-m", "hostpc.cli.main", "calibrate", "--resume",
                           str(out), "--push"], cwd=REPO, env=ENV, capture_output=True,
                          text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]  # the command it names: pushed, PASS
