"""Controller refusals end a calibration with one line naming them, exit code 4 and (once
something is journaled) the resume hint; never a traceback (issue 11: estop, busy,
offset_limit, an abort storm). An aborted pose is measured again a bounded number of times
and a resume measures the poses a storm skipped."""

from __future__ import annotations

import asyncio
import json
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from hostpc.calibrate.journal import Journal
from hostpc.calibrate.refusals import MAX_POSE_ATTEMPTS
from hostpc.robots.simulator import SimulatedController
from hostpc.transport import ControllerClient
from tests.integration.calibrate_cli import robot_args
from tests.integration.test_calibrate_sim import TOKEN, run_cli, sim_scenario, truth_rig_file

POSES = "16"


def _error_line(stderr: str) -> str:
    lines = stderr.strip().splitlines()
    assert lines and lines[-1].startswith("hostpc calibrate: error: "), stderr
    assert stderr.count("error:") == 1 and "Traceback" not in stderr, stderr
    return lines[-1]


@pytest.fixture(scope="module")
def rig(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The simulator's true camera model as a rig file (the same for every scenario here)."""
    return truth_rig_file(sim_scenario(), tmp_path_factory.mktemp("rig") / "rig.json")


@pytest.fixture
def out(tmp_path: Path) -> Path:
    """The run folder of the test's calibration (not created yet)."""
    return tmp_path / "run"


def _calibrate(capsys: pytest.CaptureFixture[str], sim: SimulatedController, rig: Path,
               out: Path, *extra: str) -> tuple[int, str, str]:
    return run_cli(capsys, "calibrate", *robot_args(sim), "--rig", str(rig), "--poses", POSES,
                   "--cv-folds", "0", "--no-report", "--out", str(out), *extra)


@contextmanager
def _peer(sim: SimulatedController, action: str, period: float = 0.05,
          after: Path | None = None) -> Iterator[None]:
    """Another (authenticated) host on the same controller, in its own thread: `hold`
    keeps a session open; `abort` sends an abort every `period` seconds (once the file
    `after` contains a push event, if given)."""
    stop = threading.Event()
    ready = threading.Event()

    def armed() -> bool:
        return after is None or (after.is_file() and '"event":"push"' in after.read_text())

    async def main() -> None:
        client = await ControllerClient.connect(sim.address.host, sim.address.port,
                                                token=TOKEN)
        try:
            ready.set()
            while not stop.is_set():
                if action == "abort" and armed():
                    await client.abort()
                await asyncio.sleep(period)
        finally:
            await client.close()

    thread = threading.Thread(target=asyncio.run, args=(main(),), daemon=True)
    thread.start()
    assert ready.wait(10)
    try:
        yield
    finally:
        stop.set()
        thread.join(10)


def _scenario(**changes: Any) -> dict[str, Any]:
    scenario = sim_scenario(**changes.pop("faults", {}))
    for section, values in changes.items():
        scenario.setdefault(section, {}).update(values)
    return scenario


def test_estop_exit_4_one_line_with_resume_hint(
        tmp_path: Path, rig: Path, out: Path,
        capsys: pytest.CaptureFixture[str]) -> None:
    with SimulatedController(_scenario(faults={"estop_after_moves": 5}), tmp_path / "s") as sim:
        code, stdout, stderr = _calibrate(capsys, sim, rig, out, "--verify-poses", "0")
    line = _error_line(stderr)
    assert code == 4 and stdout == ""
    assert line.startswith("hostpc calibrate: error: controller refused (estop): ")
    assert line.endswith(f"continue with: hostpc calibrate --resume {out}")
    assert "5 poses journaled" in line


def test_a_stop_after_the_push_says_the_controller_holds_unverified_offsets(
        tmp_path: Path, rig: Path, out: Path,
        capsys: pytest.CaptureFixture[str]) -> None:
    """An estop after the first verification pose (the fit's 16 moves, the push, one):
    the error line says the controller holds the pushed offsets, not verified, and how to
    verify or undo them (it used to say only "continue with: ... --resume"); the undo
    command it names restores the previous offsets."""
    with SimulatedController(_scenario(faults={"estop_after_moves": int(POSES) + 1}),
                             tmp_path / "s") as sim:
        before = np.asarray(sim.truth()["zero_offsets"], float)
        code, _, stderr = _calibrate(capsys, sim, rig, out, "--verify-poses", "4")
        line = _error_line(stderr)
        push = json.loads((out / "push.json").read_text())
        assert code == 4, stderr
        assert line.startswith("hostpc calibrate: error: controller refused (estop): "), line
        assert line.endswith(
            f"; {int(POSES) + 1} poses journaled in {out}; the controller holds the offsets "
            f"pushed at {push['time']} (rollback id {push['rollback_id']}), NOT verified; verify: "
            f"hostpc calibrate --resume {out}; undo: hostpc rollback --run {out}"), line
        np.testing.assert_allclose(sim.truth()["zero_offsets"], push["new_offsets"],
                                   rtol=0.0, atol=1e-12)
        code, stdout, stderr = run_cli(capsys, "rollback", "--run", str(out), "--token", TOKEN)
        assert code == 0, stderr
        np.testing.assert_array_equal(sim.truth()["zero_offsets"], before)


def test_offset_limit_is_the_controllers_own_said_once_and_nothing_half_pushed(
        tmp_path: Path, rig: Path, out: Path,
        capsys: pytest.CaptureFixture[str]) -> None:
    # issue 24: the controller's own limit is a refused push (exit 5) that says whose limit
    # it is and what to do, never a resume loop (it used to be exit 4, "--resume" again)
    with SimulatedController(_scenario(server={"offset_limit_rad": 1e-4}),
                             tmp_path / "s") as sim:
        before = sim.truth()["zero_offsets"]
        code, stdout, stderr = _calibrate(capsys, sim, rig, out, "--verify-poses", "0")
        assert code == 5
        assert "the controller's own offset limit refused the push" in stdout + stderr
        assert f"hostpc calibrate --resume {out} --push" in stdout + stderr
        assert sim.truth()["zero_offsets"] == before
        # a plain resume prints the stored result: it does not push into the same refusal
        code, stdout, stderr = run_cli(capsys, "calibrate", "--resume", str(out))
        assert code == 5 and "controller refused (offset_limit)" not in stderr
        assert "controller's own offset limit" in stdout
        assert sim.truth()["zero_offsets"] == before


def test_busy_controller_exit_4_one_line(
        tmp_path: Path, rig: Path, out: Path,
        capsys: pytest.CaptureFixture[str]) -> None:
    with SimulatedController(_scenario(server={"max_sessions": 1}), tmp_path / "s") as sim:
        with _peer(sim, "hold"):
            code, _, stderr = _calibrate(capsys, sim, rig, out)
    line = _error_line(stderr)
    assert code == 4 and "busy" in line and "too many sessions" in line
    assert not out.exists()  # nothing started: no run folder


@pytest.mark.slow
def test_abort_storm_exit_4_then_resume_measures_every_pose(
        tmp_path: Path, rig: Path, out: Path,
        capsys: pytest.CaptureFixture[str]) -> None:
    with SimulatedController(_scenario(motion={"time_scale": 0.5}), tmp_path / "s") as sim:
        with _peer(sim, "abort"):
            code, _, stderr = _calibrate(capsys, sim, rig, out, "--verify-poses", "4")
        line = _error_line(stderr)
        assert code == 4, line
        assert "measurement stopped" in line and f"--resume {out}" in line
        assert f"(attempt {MAX_POSE_ATTEMPTS} of {MAX_POSE_ATTEMPTS})" in stderr
        assert f"aborted ({MAX_POSE_ATTEMPTS} attempts)" in stderr
        # the storm is over: the resume measures the aborted poses, each once
        code, stdout, stderr = run_cli(capsys, "calibrate", "--resume", str(out))
        assert code == 0, stderr
        assert "measured: 16 of 16 fit poses" in stdout and "PASS" in stdout
    journal = Journal(out)
    assert [r.index for r in journal.records("fit") if r.ok] == list(range(16))


def test_wrong_token_exit_4_one_line(
        tmp_path: Path, rig: Path, out: Path,
        capsys: pytest.CaptureFixture[str]) -> None:
    with SimulatedController(sim_scenario(), tmp_path / "s") as sim:
        code, _, stderr = run_cli(capsys, "calibrate", *robot_args(sim, token="wrong"),
                                  "--rig", str(rig), "--out", str(out))
    line = _error_line(stderr)
    assert code == 4 and "auth" in line
    assert not out.exists()


@pytest.mark.slow
def test_lost_verification_says_so_and_stays_resumable(
        tmp_path: Path, rig: Path, out: Path,
        capsys: pytest.CaptureFixture[str]) -> None:
    with SimulatedController(_scenario(motion={"time_scale": 0.2}), tmp_path / "s") as sim:
        with _peer(sim, "abort", after=out / "journal.jsonl"):  # a storm after the push
            code, stdout, stderr = _calibrate(capsys, sim, rig, out, "--verify-poses", "3")
        line = _error_line(stderr)
        assert code == 4 and stdout == ""
        assert line.startswith("hostpc calibrate: error: verification lost: all 3 ")
        assert "the pushed offsets stay in the controller" in line
        assert line.endswith(f"measure them again with: hostpc calibrate --resume {out}")
        pushed = sim.truth()["zero_offsets"]
        code, stdout, stderr = run_cli(capsys, "calibrate", "--resume", str(out))
        assert code == 0, stderr
        assert "not verified yet: verifying now on fresh poses" in stderr
        assert "verify: 3 fresh poses" in stdout and ": PASS" in stdout
        assert sim.truth()["zero_offsets"] == pushed  # no second push
    rounds = Journal(out).events("verify_start")
    assert [r["round"] for r in rounds] == [0, 1]


def test_a_link_lost_after_the_push_says_what_the_controller_held_then(
        tmp_path: Path, rig: Path, out: Path,
        capsys: pytest.CaptureFixture[str]) -> None:
    """The link cut after the push (the stub drops a verification pose's request): the
    error line says what the controller held when the link was lost, not verified, and that
    the resume checks what it holds now (it used to say "the controller holds" as a fact,
    while a controller restarted since has its previous offsets again)."""
    # + 5: the push's set_offsets, its read-back (get_offsets), then a verification move
    with SimulatedController(_scenario(faults={"drop_after_requests": 4 + 3 * int(POSES) + 5}),
                             tmp_path / "s") as sim:
        code, _, stderr = _calibrate(capsys, sim, rig, out, "--verify-poses", "4")
    line = _error_line(stderr)
    push = json.loads((out / "push.json").read_text())
    assert code == 3, stderr
    assert line.endswith(
        f"poses journaled in {out}; the controller held the offsets pushed at {push['time']} "
        f"when the link was lost (rollback id {push['rollback_id']}), NOT verified; the resume "
        f"checks what it holds now: hostpc calibrate --resume {out}; undo: hostpc rollback "
        f"--run {out}"), line


def test_a_sim_push_cut_short_names_the_resume_that_pushes_again(
        tmp_path: Path, rig: Path, out: Path,
        capsys: pytest.CaptureFixture[str]) -> None:
    """A `--robot sim` run whose push is cut short (the stub drops set_offsets: the
    intent journaled, no answer): its simulated controller ended with the run, so the line
    names the resume that pushes again, and that command pushes (it used to name `hostpc
    rollback --run`, which finds nothing to roll back there)."""
    scenario = tmp_path / "scenario.json"
    scenario.write_text(json.dumps(sim_scenario(drop_after_requests=4 + 3 * int(POSES))))
    code, _, stderr = run_cli(capsys, "calibrate", "--robot", "sim", "--scenario",
                              str(scenario), "--rig", str(rig), "--known", "target",
                              "--poses", POSES, "--verify-poses", "0", "--cv-folds", "0",
                              "--no-report", "--out", str(out))
    line = _error_line(stderr)
    assert code == 3, stderr
    assert line.endswith(
        "a push was cut short: the simulated controller may have held the new offsets, NOT "
        "verified, and ended with the run; a resume restarts it with its initial offsets and "
        f"pushes again: hostpc calibrate --resume {out} --push"), line
    code, _, stderr = run_cli(capsys, "calibrate", "--resume", str(out), "--push")
    assert code == 0, stderr
    assert json.loads((out / "push.json").read_text())["status"] == "pushed"
