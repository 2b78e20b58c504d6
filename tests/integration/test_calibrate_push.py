"""Guarded push and rollback against the simulated controller (subprocess, loopback).

A correction beyond --max-correction is refused (exit 5, the controller untouched, the
run saved); `--resume DIR --force` pushes it without measuring again; `hostpc rollback`
restores the previous offsets, by run folder or by rollback id.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from hostpc.robots.simulator import SimulatedController
from tests.integration.test_calibrate_sim import TOKEN, run_cli, sim_scenario, truth_rig_file


def _offsets(sim: SimulatedController) -> np.ndarray:
    return np.asarray(sim.truth()["zero_offsets"], float)


@pytest.mark.slow
def test_push_guard_rail_force_and_rollback(tmp_path: Path,
                                            capsys: pytest.CaptureFixture[str]) -> None:
    rig = truth_rig_file(sim_scenario(), tmp_path / "rig.json")
    out = tmp_path / "run"
    with SimulatedController(sim_scenario(), tmp_path / "stub") as sim:
        address = f"{sim.address.host}:{sim.address.port}"
        before = _offsets(sim)
        code, stdout, stderr = run_cli(
            capsys, "calibrate", "--robot", address, "--token", TOKEN, "--rig", str(rig),
            "--known", "target", "--poses", "24", "--verify-poses", "0",
            "--max-correction", "0.05", "--no-report", "--out", str(out))
        assert code == 5, stderr
        assert "push: REFUSED" in stdout and "exceeds the limit of 0.05 deg" in stdout
        assert "--force" in stdout
        assert np.array_equal(_offsets(sim), before)  # the controller is untouched
        assert not (out / "push.json").exists()
        result = json.loads((out / "result.json").read_text())
        assert result["push"]["status"] == "refused"
        assert all(not row["pushed"] for row in result["offsets"]["joints"])

        # after checking: push the same fit with --force (no new measurements)
        journal_before = (out / "journal.jsonl").read_text()
        code, stdout, stderr = run_cli(capsys, "calibrate", "--resume", str(out), "--force",
                                       "--json")
        assert code == 0, stderr
        document = json.loads(stdout)
        assert document["push"]["status"] == "pushed"
        assert (out / "journal.jsonl").read_text().startswith(journal_before)
        joints = document["offsets"]["joints"]
        after = _offsets(sim)
        for j, row in enumerate(joints):
            if row["pushed"]:
                assert math.degrees(after[j] - before[j]) == pytest.approx(
                    row["correction_deg"], abs=1e-9)
            else:
                assert after[j] == before[j]  # q6 is unidentifiable: never pushed
        assert not joints[5]["pushed"] and all(r["pushed"] for r in joints[:5])
        push = json.loads((out / "push.json").read_text())
        assert push["previous_offsets"] == before.tolist()

        # rollback by run folder: the controller address comes from push.json
        code, stdout, stderr = run_cli(capsys, "rollback", "--run", str(out), "--token", TOKEN)
        assert code == 0, stderr
        assert "rolled back" in stdout
        assert np.array_equal(_offsets(sim), before)

        # rollback by id (the id stays valid on the controller): back to the same set
        code, stdout, stderr = run_cli(capsys, "rollback", "--robot", address, "--token",
                                       TOKEN, "--id", push["rollback_id"], "--json")
        assert code == 0, stderr
        assert json.loads(stdout)["offsets_deg"] == pytest.approx(np.degrees(before).tolist())


def test_rollback_needs_a_run_or_an_id(capsys: pytest.CaptureFixture[str],
                                       tmp_path: Path) -> None:
    code, _, stderr = run_cli(capsys, "rollback", "--robot", "127.0.0.1:1")
    assert code == 2 and stderr.count("\n") == 1
    code, _, stderr = run_cli(capsys, "rollback", "--run", str(tmp_path))
    assert code == 2 and "pushed no offsets" in stderr and stderr.count("\n") == 1


@pytest.mark.slow
def test_a_rolled_back_runs_summary_no_longer_reads_its_verification_as_the_robots(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    rig = truth_rig_file(sim_scenario(), tmp_path / "rig.json")
    out = tmp_path / "run"
    with SimulatedController(sim_scenario(), tmp_path / "stub") as sim:
        address = f"{sim.address.host}:{sim.address.port}"
        code, stdout, stderr = run_cli(
            capsys, "calibrate", "--robot", address, "--token", TOKEN, "--rig", str(rig),
            "--known", "target", "--poses", "24", "--verify-poses", "4", "--no-report",
            "--out", str(out))
        assert code == 0, stderr
        assert "\nverify: 4 fresh poses" in stdout and ": PASS" in stdout
        code, stdout, stderr = run_cli(capsys, "rollback", "--run", str(out), "--token", TOKEN)
        assert code == 0, stderr
    summary = (out / "summary.txt").read_text()
    assert summary.startswith("ROLLED BACK at ")
    verify = [line for line in summary.splitlines() if line.startswith("verify")]
    assert verify and all(line.startswith("verify (of the offsets since rolled back, no "
                                          "longer in the controller): ") for line in verify)


def test_rollback_of_a_simulated_run_needs_no_controller(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """`--robot sim`'s controller lived only as long as its run: one line, nothing dialled
    (push.json names the dead simulator's port)."""
    out = tmp_path / "run"
    code, _, stderr = run_cli(capsys, "calibrate", "--robot", "sim", "--poses", "12",
                              "--verify-poses", "0", "--no-report", "--out", str(out))
    assert code == 0, stderr
    assert json.loads((out / "push.json").read_text())["status"] == "pushed"
    code, stdout, stderr = run_cli(capsys, "rollback", "--run", str(out), "--timeout", "30")
    assert code == 2 and stderr.count("\n") == 1, stderr
    assert "ran against `--robot sim`" in stderr and "nothing left to roll back" in stderr
