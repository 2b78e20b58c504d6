"""The verification's false-FAIL rate, end to end (the 10-seed version of
bench/bench_verdicts.py): correct calibrations of the simulated controller pass at the design
rate alpha = 1 %, and the forced push of a model missing a hidden effect FAILs."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from hostpc.robots.simulator import load_scenario_file
from tests.integration.test_calibrate_sim import run_cli, sim_scenario, truth_rig_file

REPO = Path(__file__).resolve().parents[2]
HIDDEN = REPO / "controller_stub" / "scenarios" / "stereo_hidden_compliance.yaml"
SEEDS = range(10)


def _verify(capsys: pytest.CaptureFixture[str], out: Path, *args: str) -> dict:  # type: ignore[type-arg]
    code, stdout, stderr = run_cli(capsys, "calibrate", "--robot", "sim", "--cv-folds", "0",
                                   "--poses", "30", "--candidates", "500",
                                   "--no-report", "--json", "--out", str(out), *args)
    assert code in (0, 6), stderr
    document = json.loads(stdout)
    assert document["push"]["status"] == "pushed"
    assert code == (6 if document["verify"]["verdict"] == "FAIL" else 0)
    return document["verify"]  # type: ignore[no-any-return]


@pytest.mark.slow
def test_ten_correct_calibrations_pass_at_the_design_rate(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    rig = truth_rig_file(sim_scenario(), tmp_path / "rig.json")
    verdicts = [_verify(capsys, tmp_path / f"run{seed}", "--rig", str(rig), "--seed", str(seed))
                for seed in SEEDS]
    for verify in verdicts:
        assert verify["alpha"] == 0.01 and verify["dof"] == 30 and verify["n_poses"] == 10
    # alpha = 1 %: two or more FAILs in 10 runs has probability 0.4 %
    assert sum(v["verdict"] == "FAIL" for v in verdicts) <= 1, verdicts


@pytest.mark.slow
def test_forced_push_of_an_inadequate_model_fails(tmp_path: Path,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    rig = truth_rig_file(load_scenario_file(HIDDEN), tmp_path / "rig.json")
    for seed in (0, 1):
        verify = _verify(capsys, tmp_path / f"run{seed}", "--scenario", str(HIDDEN),
                         "--known", "target", "--force", "--rig", str(rig), "--seed", str(seed))
        assert verify["verdict"] == "FAIL" and verify["p_value"] < 1e-6
