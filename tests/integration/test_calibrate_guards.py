"""The calibrate run's guard rails and honesty, beyond the correction limit:

- a fit whose chi2/dof is above its chi-square band refuses the push (exit 5), and the
  verification that follows is labelled a model check (nothing pushed), never PASS;
- the push's intent is journaled before the controller is written: a push cut short is
  settled on resume and by `hostpc rollback --run` from the controller's offsets;
- a deliberate rollback is not undone by `--resume` unless it asks (--push/--force);
- SIGTERM stops `hostpc calibrate` like Ctrl-C (simulator stopped, one line saying how to
  resume), and the resumed `--robot sim` run's sample time `t` keeps increasing.
"""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from hostpc.calibrate.push import plan_push
from hostpc.diagnostics.adequacy import chi2_dof_upper
from hostpc.fitting import fit
from hostpc.robots.simulator import SimulatedController, load_scenario_file
from hostpc.synthesize import synthesize_stereo_target
from tests.integration.test_calibrate_sim import TOKEN, run_cli, sim_scenario, truth_rig_file

REPO = Path(__file__).resolve().parents[2]
HIDDEN_COMPLIANCE = REPO / "controller_stub" / "scenarios" / "stereo_hidden_compliance.yaml"
OFFSETS = {f"joint_offsets.q{j}": 0.002 * (-1) ** j for j in range(1, 7)}


def _inflated(dataset, factor: float):  # type: ignore[no-untyped-def]
    """The dataset with its stated covariances multiplied by `factor` (a pixel floor)."""
    samples = replace(dataset.samples, cov=dataset.samples.cov * factor)
    return replace(dataset, samples=samples)


# ------------------------------------------------------------------ pure: the two figures


def test_chi2_band_refuses_an_inadequate_model_only() -> None:
    # the band's upper edge is the chi-square 1e-3 upper quantile over dof
    assert chi2_dof_upper(100) == pytest.approx(149.449 / 100, rel=1e-4)
    old = np.zeros(6)
    known = ("tool", "target")
    # a hidden encoder scale on joint 2 the model lacks: chi2/dof far above the band
    hidden = synthesize_stereo_target({**OFFSETS, "encoder_scale.s2": 2e-3}, n_samples=60,
                                      seed=1, known=known).dataset
    lean = fit(hidden, "joint_offsets", cv_folds=0)
    assert lean.converged and lean.chi2_dof > chi2_dof_upper(lean.dof)
    plan = plan_push(lean, old, dataset_file="RUN/dataset.json")
    assert plan.refused is not None
    assert plan.refused.startswith("the model does not explain the measurements (chi2/dof ")
    assert "run `hostpc diagnose RUN/dataset.json` and rerun with the effect it names" in (
        plan.refused)
    assert plan.refused.endswith("or push anyway with --force")
    assert plan_push(lean, old, force=True).refused is None
    # overstated covariances (chi2/dof far BELOW the band) are no reason to refuse
    adequate = _inflated(synthesize_stereo_target(OFFSETS, n_samples=60, seed=2,
                                                  known=known).dataset, 4.0)
    good = fit(adequate, "joint_offsets", cv_folds=0)
    assert good.chi2_dof < 0.5
    assert plan_push(good, old).refused is None


# ------------------------------------------------------------------ end to end


def _offsets(sim: SimulatedController) -> np.ndarray:
    return np.asarray(sim.truth()["zero_offsets"], float)


@pytest.mark.slow
def test_inadequate_model_refuses_the_push_and_verify_is_a_model_check(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    scenario = load_scenario_file(HIDDEN_COMPLIANCE)
    rig = truth_rig_file(scenario, tmp_path / "rig.json")
    out = tmp_path / "run"
    code, stdout, stderr = run_cli(
        capsys, "calibrate", "--robot", "sim", "--scenario", str(HIDDEN_COMPLIANCE),
        "--known", "target", "--rig", str(rig), "--poses", "40", "--verify-poses", "4",
        "--cv-folds", "0", "--no-report", "--out", str(out))
    assert code == 5, stderr
    refusal = [line for line in stderr.splitlines() if line.startswith("push refused:")]
    assert len(refusal) == 1
    assert refusal[0].startswith("push refused: the model does not explain the measurements "
                                 "(chi2/dof ")
    assert f"run `hostpc diagnose {out}/dataset.json` and rerun" in refusal[0]
    assert "push: REFUSED: the model does not explain" in stdout
    assert "model check on fresh poses (nothing pushed)" in stdout
    assert "PASS" not in stdout and "verify:" not in stdout
    result = json.loads((out / "result.json").read_text())
    assert result["push"]["status"] == "refused" and result["verify"]["kind"] == "model_check"
    assert result["fit"]["chi2_dof"] > result["fit"]["chi2_dof_upper"]
    assert not (out / "push.json").exists()


@pytest.mark.slow
def test_push_intent_is_journaled_first_and_settled_on_resume(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    poses = 16
    rig = truth_rig_file(sim_scenario(), tmp_path / "rig.json")
    out = tmp_path / "run"
    # requests: get_state, get_offsets, (move, capture, robot-time clock reading) per pose,
    # then set_offsets: dropped (not executed, the link cut) -> the run stops after
    # journaling its intent; + 2: the clock readings (get_state) after the rig and after
    # the poses
    scenario = sim_scenario(drop_after_requests=4 + 3 * poses)
    with SimulatedController(scenario, tmp_path / "stub") as sim:
        address = f"{sim.address.host}:{sim.address.port}"
        before = _offsets(sim)
        code, _, stderr = run_cli(
            capsys, "calibrate", "--robot", address, "--token", TOKEN, "--rig", str(rig),
            "--known", "target", "--poses", str(poses), "--verify-poses", "0",
            "--cv-folds", "0", "--no-report", "--out", str(out))
        assert code == 3, stderr
        assert stderr.strip().splitlines()[-1].endswith(
            "a push was cut short: the controller may hold the new offsets, NOT verified; "
            f"settle and verify it with: hostpc calibrate --resume {out} (undo: hostpc "
            f"rollback --run {out})"), stderr
        events = [json.loads(line) for line in (out / "journal.jsonl").read_text().splitlines()]
        assert events[-1]["event"] == "push_intent"
        assert events[-1]["previous_offsets"] == before.tolist() and events[-1]["time"]
        intended = events[-1]["new_offsets"]
        assert json.loads((out / "push.json").read_text())["status"] == "intent"
        assert np.array_equal(_offsets(sim), before)

        # rollback of an intent the controller never saw: nothing to do
        code, stdout, stderr = run_cli(capsys, "rollback", "--run", str(out), "--token", TOKEN)
        assert code == 0 and "nothing to roll back" in stdout, stderr
        assert np.array_equal(_offsets(sim), before)

        # resume: the intent did not reach the controller -> push now
        code, _, stderr = run_cli(capsys, "calibrate", "--resume", str(out))
        assert code == 0 and "did not reach the controller" in stderr, stderr
        np.testing.assert_allclose(_offsets(sim), intended, rtol=0, atol=1e-12)

        # a push whose write reached the controller but whose result was never recorded
        # (the run stopped before its push result: no push event, no result written)
        lines = (out / "journal.jsonl").read_text().splitlines(keepends=True)
        # (stopped before the controller's answer was journaled: push_written is the
        # answer's record, with the rollback id)
        assert [json.loads(line)["event"] for line in lines[-3:]] == [
            "push_written", "push", "result"]
        (out / "journal.jsonl").write_text("".join(lines[:-3]))
        (out / "result.json").unlink()
        record = json.loads((out / "push.json").read_text())
        (out / "push.json").write_text(json.dumps({**record, "status": "intent",
                                                   "rollback_id": None}))
        code, stdout, stderr = run_cli(capsys, "calibrate", "--resume", str(out), "--json")
        assert code == 0 and "recorded as pushed" in stderr, stderr
        document = json.loads(stdout)
        assert document["push"]["status"] == "pushed" and document["push"]["recovered"]
        assert json.loads((out / "push.json").read_text())["status"] == "pushed"
        code, stdout, stderr = run_cli(capsys, "rollback", "--run", str(out), "--token", TOKEN)
        assert code == 0 and "wrote the saved previous offsets" in stdout, stderr
        assert np.array_equal(_offsets(sim), before)
        # a second rollback of the same push is refused: the controller may hold a later
        # run's verified offsets by now, which it would silently discard
        code, stdout, stderr = run_cli(capsys, "rollback", "--run", str(out), "--token", TOKEN)
        assert code == 2 and "rolled back already" in stderr, stderr
        assert f"hostpc status --robot {address}" in stderr  # the run's own controller

        # the deliberate rollback is not undone by a plain resume ...
        journal_before = (out / "journal.jsonl").read_text()
        code, stdout, stderr = run_cli(capsys, "calibrate", "--resume", str(out))
        assert code == 0, stderr
        assert "was rolled back" in stderr and "--push" in stderr
        assert "push: not repeated" in stdout
        assert np.array_equal(_offsets(sim), before)
        assert "push_intent" not in (out / "journal.jsonl").read_text()[len(journal_before):]
        # ... only by one that asks
        code, _, stderr = run_cli(capsys, "calibrate", "--resume", str(out), "--push")
        assert code == 0, stderr
        np.testing.assert_allclose(_offsets(sim), intended, rtol=0, atol=1e-12)
        summary = (out / "summary.txt").read_text()
        assert f"undo with hostpc rollback --run {out}" in summary


def _port_open(address: str) -> bool:
    host, port = address.rsplit(":", 1)
    try:
        with socket.create_connection((host, int(port)), timeout=1.0):
            return True
    except OSError:
        return False


def _samples(journal: Path) -> int:
    """The measured samples the run's journal holds (its "sample" events; a line still being
    written is not one yet)."""
    count = 0
    for line in journal.read_text().splitlines() if journal.is_file() else ():
        try:
            count += json.loads(line).get("event") == "sample"
        except ValueError:
            pass
    return count


@pytest.mark.slow
def test_sigterm_stops_cleanly_and_a_sim_resume_keeps_time_increasing(tmp_path: Path) -> None:
    rig = truth_rig_file(sim_scenario(), tmp_path / "rig.json")
    out = tmp_path / "run"
    poses = 10
    # paced at the simulator's own speed (time scale 1): after the first sample the other 9
    # poses take at least 9 s of wall time (each >= 1 s simulated: move, settle, capture),
    # and load only makes them longer, so the signal sent on the first sample always lands
    # mid-measurement
    command = [sys.executable, "-m", "hostpc.cli.main", "calibrate", "--robot", "sim",
               "--rig", str(rig), "--poses", str(poses), "--verify-poses", "0",
               "--cv-folds", "0", "--no-report", "--time-scale", "1", "--out", str(out)]
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    process = subprocess.Popen(command, cwd=REPO, env=env, stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True)
    journal = out / "journal.jsonl"
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and process.poll() is None and not _samples(journal):
        time.sleep(0.02)
    assert process.poll() is None and _samples(journal), "no sample measured while running"
    process.send_signal(signal.SIGTERM)
    _, stderr = process.communicate(timeout=30)
    assert process.returncode == 143, stderr
    last = stderr.strip().splitlines()[-1]  # "interrupted (...abort sent...)" during a move
    assert last.startswith("hostpc calibrate: interrupted") and last.endswith(
        f": continue with hostpc calibrate --resume {out}"), last
    address = json.loads((out / "run.json").read_text())["robot"]["address"]
    assert not _port_open(address)  # the simulator was stopped by the `with` block
    assert 1 <= _samples(journal) < poses

    # the resume restarts the simulator (its clock starts again): t keeps increasing
    done = subprocess.run([sys.executable, "-m", "hostpc.cli.main", "calibrate", "--resume",
                           str(out)], cwd=REPO, env=env, capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "clock restarted" in done.stderr
    samples = json.loads((out / "dataset.json").read_text())["samples"]
    t = np.array([s["t"] for s in samples])
    assert t.size == poses and np.all(np.diff(t) > 0), t
