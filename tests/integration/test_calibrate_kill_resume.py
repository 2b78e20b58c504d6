"""A calibration stopped at any phase resumes to a verdict that matches the controller's
true state (issue 11, "Done when"): no sample lost or duplicated, no double push.

One complete run against a simulated controller gives the journal; each case below is the
run folder as it stood when the host (or the controller) died in one phase: its journal cut
after that phase's last durable line, and a controller in the state that phase leaves
behind (the run's initial offsets, or the pushed ones). The resume must then say exactly
what happened, and finish.
"""

from __future__ import annotations

import asyncio
import json
import shutil
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest

from hostpc.calibrate.journal import Journal
from hostpc.calibrate.robot_time import robot_time_document
from hostpc.robots.simulator import SimulatedController
from hostpc.transport import ControllerClient
from tests.integration.calibrate_cli import resume_on, robot_args
from tests.integration.test_calibrate_sim import TOKEN, run_cli, sim_scenario, truth_rig_file

N_FIT, N_VERIFY = 16, 4
RESULT_FILES = ("result.json", "summary.txt", "verify.json", "verify_dataset.json",
                "dataset.json", "fit.json", "push.json")


def _events(run: Path) -> list[dict]:  # type: ignore[type-arg]
    return [json.loads(line) for line in (run / "journal.jsonl").read_text().splitlines()]


def _set_offsets(sim: SimulatedController, offsets: list[float]) -> None:
    async def write() -> None:
        client = await ControllerClient.connect(sim.address.host, sim.address.port,
                                                token=TOKEN)
        try:
            await client.set_offsets(np.asarray(offsets))
        finally:
            await client.close()

    asyncio.run(write())


def _stopped_run(complete: Path, tmp_path: Path, n_lines: int | None = None) -> Path:
    """A copy of the complete run folder in tmp_path/run as it was when the journal held
    its first n_lines lines (None: the whole finished run, unchanged)."""
    run = tmp_path / "run"
    shutil.copytree(complete, run)
    if n_lines is None:
        return run
    lines = (complete / "journal.jsonl").read_text().splitlines(keepends=True)[:n_lines]
    (run / "journal.jsonl").write_text("".join(lines))
    kinds = [json.loads(line)["event"] for line in lines]
    for name in RESULT_FILES:
        if name == "push.json" and "push_intent" in kinds:
            continue
        (run / name).unlink(missing_ok=True)
    return run


@contextmanager
def _controller(tmp_path: Path, offsets: list[float] | None = None
                ) -> Iterator[SimulatedController]:
    """A fresh simulated controller (the run's initial offsets, or ``offsets`` written)."""
    with SimulatedController(sim_scenario(), tmp_path / "stub") as sim:
        if offsets is not None:
            _set_offsets(sim, offsets)
        yield sim


@pytest.fixture(scope="module")
def complete_run(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, dict]:  # type: ignore[type-arg]
    base = tmp_path_factory.mktemp("complete")
    rig = truth_rig_file(sim_scenario(), base / "rig.json")
    run = base / "run"
    with SimulatedController(sim_scenario(), base / "stub") as sim:
        code = _cli(sim, "--rig", str(rig), "--poses", str(N_FIT), "--verify-poses",
                    str(N_VERIFY), "--out", str(run))
        assert code == 0
    push = next(e for e in _events(run) if e["event"] == "push")
    return run, rig, push


def _cli(sim: SimulatedController, *args: str) -> int:
    from hostpc.cli.main import main

    return main(["calibrate", *robot_args(sim), "--cv-folds", "0", "--no-report", *args])


def _line_after(run: Path, kind: str, nth: int = 1) -> int:
    """Number of journal lines up to and including the nth event of `kind`."""
    seen = 0
    for number, event in enumerate(_events(run), start=1):
        if event["event"] == kind:
            seen += 1
            if seen == nth:
                return number
    raise AssertionError(f"no {kind} #{nth}")


# phase -> (journal lines kept, controller has the pushed offsets, expected resume message)
PHASES = {
    "planning": (lambda run: 0, False, "resuming"),
    "capture": (lambda run: 7, False, "resuming"),
    "fit / before push": (lambda run: N_FIT, False, "resuming"),
    "mid push, write lost": (lambda run: _line_after(run, "push_intent"), False,
                             "did not reach the controller"),
    "mid push, write done": (lambda run: _line_after(run, "push_intent"), True,
                             "reached the controller"),
    "after push": (lambda run: _line_after(run, "push"), True,
                   "not verified yet: verifying now on fresh poses"),
    "mid verify": (lambda run: _line_after(run, "verify_start") + 2, True,
                   "not verified yet: verifying now on fresh poses"),
}


@pytest.mark.slow
@pytest.mark.parametrize("phase", list(PHASES))
def test_resume_after_a_stop_in_each_phase(phase: str, complete_run, tmp_path: Path,  # type: ignore[no-untyped-def]
                                           capsys: pytest.CaptureFixture[str]) -> None:
    complete, _, push = complete_run
    keep, pushed, message = PHASES[phase]
    run = _stopped_run(complete, tmp_path, keep(complete))
    intents_before = sum(e["event"] == "push_intent" for e in _events(run))
    with _controller(tmp_path, push["new_offsets"] if pushed else None) as sim:
        capsys.readouterr()
        code, stdout, stderr = resume_on(capsys, sim, run)
        offsets = sim.truth()["zero_offsets"]
        remaining = np.asarray(sim.truth()["zero_errors"])
    assert code == 0, stderr
    assert message in stderr
    # the verdict matches the controller: it has the pushed offsets (the ones pushed
    # before the stop, if it came after the push), and they are right
    events = _events(run)
    new = [e for e in events if e["event"] == "push"][-1]["new_offsets"]
    np.testing.assert_allclose(offsets, new, rtol=0, atol=1e-12)
    if intents_before:
        np.testing.assert_allclose(new, push["new_offsets"], rtol=0, atol=1e-12)
    assert "push: written" in stdout and "verify:" in stdout and ": PASS" in stdout
    assert np.all(np.abs(np.degrees(remaining[1:5])) < 0.002)  # J1, J6: not identifiable
    # no double push: the controller written once (an intent that never reached it is
    # settled as not pushed, then pushed: its one write)
    assert sum(e["event"] == "push" for e in events) == 1
    if pushed:
        assert sum(e["event"] == "push_intent" for e in events) == intents_before
    # no sample lost or duplicated: each fit pose once; each verify pose once in its round
    journal = Journal(run)
    fit_lines = [e for e in events if e["event"] == "sample" and e["phase"] == "fit"]
    assert sorted(e["index"] for e in fit_lines) == list(range(N_FIT))
    verify_lines = [e["index"] for e in events if e["event"] == "sample"
                    and e["phase"] == "verify"]
    assert len(verify_lines) == len(set(verify_lines))
    rounds = [e for e in events if e["event"] == "verify_start"]
    first = rounds[-1]["first"]
    assert [r.index for r in journal.records("verify")
            if first <= r.index < first + N_VERIFY] == list(range(first, first + N_VERIFY))
    np.testing.assert_allclose(rounds[-1]["offsets"], new, rtol=0, atol=1e-12)


@pytest.mark.slow
def test_finished_run_is_printed_unchanged(complete_run, tmp_path: Path,  # type: ignore[no-untyped-def]
                                           capsys: pytest.CaptureFixture[str]) -> None:
    complete, _, push = complete_run
    run = _stopped_run(complete, tmp_path)
    before = {p.name: p.read_bytes() for p in run.iterdir() if p.is_file()}
    with _controller(tmp_path, push["new_offsets"]) as sim:
        for extra in ((), ("--max-correction", "1", "--force")):
            code, stdout, stderr = resume_on(capsys, sim, run, *extra)
            assert code == 0, stderr
            assert "already pushed and verified (PASS)" in stderr
            assert stdout.strip() == before["summary.txt"].decode().strip()
    after = {p.name: p.read_bytes() for p in run.iterdir() if p.is_file()}
    assert after == before  # nothing changed: no file, not even the journal


@pytest.mark.slow
def test_restarted_controller_lost_the_push(complete_run, tmp_path: Path,  # type: ignore[no-untyped-def]
                                            capsys: pytest.CaptureFixture[str]) -> None:
    complete, _, push = complete_run
    run = _stopped_run(complete, tmp_path, _line_after(complete, "push"))
    with _controller(tmp_path) as sim:  # initial offsets
        code, stdout, stderr = resume_on(capsys, sim, run)
        assert code == 4 and stdout == ""
        line = stderr.strip().splitlines()[-1]
        assert line.startswith("hostpc calibrate: error: push lost: ")
        assert f"hostpc calibrate --resume {run} --push" in line
        assert "rolled back" not in stderr
        code, stdout, stderr = resume_on(capsys, sim, run, "--push")
        assert code == 0, stderr
        assert "push: written" in stdout and ": PASS" in stdout
        np.testing.assert_allclose(sim.truth()["zero_offsets"], push["new_offsets"], rtol=0,
                                   atol=1e-12)


@pytest.mark.slow
def test_rollback_refuses_to_discard_a_later_push_unless_told(  # type: ignore[no-untyped-def]
        complete_run, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    complete, _, push = complete_run
    run = _stopped_run(complete, tmp_path)
    with _controller(tmp_path, push["new_offsets"]) as sim:  # this run's push (rb-1 too)
        later = (np.asarray(push["new_offsets"]) + 1e-4).tolist()
        _set_offsets(sim, later)  # another host's later push
        # refused, nothing written: the controller holds another push than this run's
        code, stdout, stderr = run_cli(capsys, "rollback", "--run", str(run),
                                       *robot_args(sim))
        assert code == 2 and "--discard-later-push" in stderr, stderr
        np.testing.assert_allclose(sim.truth()["zero_offsets"], later, rtol=0, atol=1e-12)
        # the override the refusal names discards it
        code, stdout, stderr = run_cli(capsys, "rollback", "--run", str(run),
                                       *robot_args(sim), "--discard-later-push")
        assert code == 0, stderr
        np.testing.assert_allclose(sim.truth()["zero_offsets"], push["previous_offsets"],
                                   rtol=0, atol=1e-12)
    rollback = _events(run)[-1]
    assert rollback["event"] == "rollback"


@pytest.mark.slow
def test_robot_time_of_a_killed_verify_session_is_kept(complete_run, tmp_path: Path,  # type: ignore[no-untyped-def]
                                                        capsys: pytest.CaptureFixture[str]) -> None:
    """kill -9 after two verification poses: the journal already holds their robot time
    (each pose's time is journaled with it), and the resumed run's result adds it to the
    resumed session's (before: only phase ends were journaled, so the killed session's
    verification time was lost)."""
    complete, _, push = complete_run
    motion = sim_scenario().get("motion", {})
    per_pose = float(motion.get("settle_s", 0.3)) + float(motion.get("capture_s", 0.1))
    verify_start = _line_after(complete, "verify_start")
    second = next(number for number, event in enumerate(_events(complete), start=1)
                  if number > verify_start and event["event"] == "sample"
                  and event["phase"] == "verify" and event["index"] == 1)
    run = _stopped_run(complete, tmp_path, second + 1)  # the second verify pose + 1 line
    killed = robot_time_document(Journal(run))["verify"]
    assert killed >= 2 * per_pose  # two settled, captured poses (and the moves to them)
    with _controller(tmp_path, push["new_offsets"]) as sim:
        code, _, stderr = resume_on(capsys, sim, run)
    assert code == 0, stderr
    total = json.loads((run / "result.json").read_text())["robot_time_s"]
    assert total["verify"] >= killed + (N_VERIFY - 2) * per_pose
    assert total["total"] == pytest.approx(total["rig"] + total["measure"] + total["verify"])
