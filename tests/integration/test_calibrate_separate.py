"""Separating experiments against the real controller stub (`hostpc calibrate --robot sim`,
a stub subprocess on a free loopback port): a single-sphere probe run whose hidden joint
compliance diagnose cannot tell from geometry; `--resume RUN --separate A,B` measures the
poses that tell them apart, and the right one becomes significant, the wrong one not."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from tests.integration.conftest import BASE_SCENARIO, merge
from tests.integration.test_calibrate_sim import run_cli

PAIR = "joint_compliance,geometry"
#: joints 2 and 3 bend under gravity (rad/N m): 0.4 x the stereo example's, small enough
#: that 100 contacts on one sphere cannot tell it from a link-length error
COMPLIANCE = [0.0, 0.8e-5, 1.0e-5, 0.0, 0.0, 0.0]


def _fit_records(run: Path) -> list[int]:
    lines = [json.loads(line) for line in (run / "journal.jsonl").read_text().splitlines()]
    return [e["index"] for e in lines if e.get("event") == "sample" and e["phase"] == "fit"]


@pytest.mark.slow
def test_separating_poses_choose_the_hidden_effect(tmp_path: Path,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    scenario = tmp_path / "scenario.json"
    scenario.write_text(json.dumps(merge(BASE_SCENARIO, {"truth": {
        "probe_trigger_latency_s": 0.0, "joint_compliance": COMPLIANCE}})))
    run = tmp_path / "run"
    code, _, err = run_cli(capsys, "calibrate", "--robot", "sim", "--scenario", str(scenario),
                           "--method", "sphere_probe", "--poses", "100", "--verify-poses", "0",
                           "--seed", "3", "--cv-folds", "0", "--out", str(run),
                           "--no-report")
    assert code == 5, err  # the model guard refuses the push: the model misses an effect

    # the default single-sphere plan: both significant, neither given the other
    code, out, err = run_cli(capsys, "diagnose", str(run / "dataset.json"), "--json")
    assert code == 1, err  # not adequate
    confounded = json.loads(out)["confounded"]
    pair = next(c for c in confounded if set(c["effects"]) == set(PAIR.split(",")))
    assert pair["confounded"] and pair["winner"] is None
    assert pair["next"] == f"hostpc calibrate --resume {run} --separate " \
        + ",".join(pair["effects"])
    code, text, _ = run_cli(capsys, "diagnose", str(run / "dataset.json"))
    assert f"separate them: hostpc calibrate --resume {run} --separate" in text

    measured = _fit_records(run)
    code, out, err = run_cli(capsys, "calibrate", "--resume", str(run), "--separate", PAIR,
                             "--no-report")
    assert code == 0, err
    assert "separate joint_compliance and geometry:" in err and "predicted" in err
    added = _fit_records(run)
    assert len(added) > len(measured) and set(measured) < set(added)
    result = json.loads((run / "separation.json").read_text())
    assert result["winner"] == "joint_compliance", result
    compliance, geometry = result["tests"]
    assert compliance["effect"] == "joint_compliance" and compliance["significant"]
    assert geometry["effect"] == "geometry" and not geometry["significant"]
    assert result["samples"] == len(added)
    assert result["next"] == f"hostpc calibrate --resume {run} --effects +joint_compliance"
    # a --separate resume measures and tests; it pushes only with its own --push
    events = [json.loads(line).get("event") for line in
              (run / "journal.jsonl").read_text().splitlines()]
    assert "push" not in events and "push_intent" not in events
    assert json.loads((run / "run.json").read_text())["settings"]["push"] is True

    # a resume with the same pair measures nothing again and comes to the same verdict
    code, _, err = run_cli(capsys, "calibrate", "--resume", str(run), "--separate",
                           "geometry,joint_compliance", "--no-report")
    assert code == 0, err
    assert _fit_records(run) == added
    assert json.loads((run / "separation.json").read_text())["winner"] == "joint_compliance"


@pytest.mark.parametrize(("args", "words"), [
    (("--robot", "sim", "--separate", PAIR), "--separate needs --resume RUN"),
    (("--resume", "RUN", "--separate", "joint_complianc,geometry"), "unknown"),
    (("--resume", "RUN", "--separate", "geometry"), "two different"),
    (("--resume", "RUN", "--separate", "tool,geometry"), "frame"),
])
def test_a_bad_separate_is_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                    args: tuple[str, ...], words: str) -> None:
    run = tmp_path / "run"
    run.mkdir()
    (run / "journal.jsonl").write_text("")
    args = tuple(str(run) if a == "RUN" else a for a in args)
    code, out, err = run_cli(capsys, "calibrate", *args)
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and words in lines[0], err
    assert "hostpc calibrate --resume" in lines[0]
    assert "--candidates" not in lines[0]  # an option the user did not give
