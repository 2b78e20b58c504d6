"""A cell reference against the simulated controller: a motor swap on J1 and J6 is recovered
only with a reference, a moved frame is named and nothing is pushed, and a resume refits
with another reference or known set (hostpc.calibrate.reference, run_reference).

Each method's world: every frame estimated (nothing declared known). The reference is
recorded from a run whose J1 and J6 zeros are good (zero error), then the same cell gets a
fresh 2 deg error on J1 and J6 (small errors elsewhere, another noise seed).
"""

from __future__ import annotations

import asyncio
import dataclasses
import json
import math
from pathlib import Path
from typing import Any

import pytest

from hostpc.calibrate.journal import Journal
from hostpc.cli.main import main
from hostpc.methods.base import NullProgress
from hostpc.robots.simulator import default_sim_scenario
from tests.integration.test_calibrate_sim import run_cli

SMALL = [0.0, 0.0021, -0.0013, 0.0017, -0.0009, 0.0]
SWAP = math.radians(2.0)


def world(method: str, seed: int, zero_errors: list[float], *, tip_off_axis: bool = False,
          **sections: Any) -> dict[str, Any]:
    """The method's default simulated world with these zero errors; the probe's tip on the
    flange axis (no frame can give J6: the plan says so), or off it."""
    scenario = default_sim_scenario(method=method)
    scenario["seed"] = seed
    scenario["truth"] = {**scenario.get("truth", {}), "zero_errors": zero_errors}
    if tip_off_axis:
        scenario["probe"] = {**scenario["probe"], "tip": [0.03, -0.02, 0.12]}
    for key, value in sections.items():
        scenario[key] = {**scenario.get(key, {}), **value}
    return scenario


def calibrate(out: Path, scenario: dict[str, Any], method: str, *extra: str
              ) -> tuple[int, dict[str, Any]]:
    """`hostpc calibrate --robot sim --scenario` (every frame estimated) -> (exit, result)."""
    scenario_file = out.parent / f"{out.name}.scenario.json"
    scenario_file.write_text(json.dumps(scenario))
    code = main(["calibrate", "--robot", "sim", "--method", method, "--scenario",
                 str(scenario_file), "--out", str(out), "--no-report",
                 "--max-correction", "5", *extra])
    return code, json.loads((out / "result.json").read_text())


def recorded(tmp: Path, method: str, tip_off_axis: bool = False
             ) -> tuple[Path, dict[str, Any], tuple[str, ...]]:
    """Run the recording world and record its reference: (file, result, --rig option)."""
    code, document = calibrate(tmp / "record",
                               world(method, 3, SMALL, tip_off_axis=tip_off_axis), method)
    assert code == 0
    reference = tmp / "cell_ref.json"
    assert main(["reference", "record", "--run", str(tmp / "record"), "--out",
                 str(reference)]) == 0
    rig = tmp / "cell_ref.rig.json"
    return reference, document, (("--rig", str(rig)) if rig.is_file() else ())


OFF_AXIS_TIP = pytest.param("sphere_probe", True, id="sphere_probe-tip-off-axis")
ON_AXIS_TIP = pytest.param("sphere_probe", False, id="sphere_probe-tip-on-axis")


@pytest.mark.slow
@pytest.mark.parametrize(("method", "tip_off_axis"), [
    ("stereo_target", False), ("world_point", False), ON_AXIS_TIP, OFF_AXIS_TIP])
def test_motor_swap_on_j1_and_j6_is_recovered_with_a_reference(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], method: str,
        tip_off_axis: bool) -> None:
    reference, before, rig = recorded(tmp_path, method, tip_off_axis)
    # physics: a stylus tip on the flange axis never sees J6, whatever frames are known
    blind_j6 = method == "sphere_probe" and not tip_off_axis
    # without a reference the plan and the fit say J1 and J6 cannot be calibrated
    assert before["known"] == []
    assert set(before["plan"]["joints"]["not_calibrated"]) == {"J1", "J6"}
    assert [e is None for e in before["truth"]["joint_offsets_error_deg"]] == [
        True, False, False, False, False, True]
    held = {text.split(" ", 1)[0] for text in before["fit"]["unidentifiable"]}
    assert held == {"joint_offsets.q1", "joint_offsets.q6"}
    # the swap: +2 deg on J1 and J6; with the reference every joint is recovered
    swapped = [SWAP, *SMALL[1:5], SWAP]
    code, document = calibrate(tmp_path / "swap",
                               world(method, 4, swapped, tip_off_axis=tip_off_axis), method,
                               "--reference", str(reference), *rig)
    capsys.readouterr()
    assert code == 0, (document["push"]["reason"], document["reference_check"])
    joints = document["plan"]["joints"]
    if blind_j6:
        assert joints["from_reference"] == ["J1"] and list(joints["not_calibrated"]) == ["J6"]
        assert "no effect on these measurements" in joints["not_calibrated"]["J6"]
    else:
        assert joints["from_reference"] == ["J1", "J6"] and joints["not_calibrated"] == {}
    errors = document["truth"]["joint_offsets_error_deg"]
    if blind_j6:
        errors = errors[:5]
    # the plan aims at every joint the run calibrates, those the reference resolves too:
    # each reaches the target sigma, or one the reference's frames bound (world_point's J6:
    # its markers' rotation about the flange axis, about 0.01 deg) is planned to that bound
    plan = document["plan"]
    sigmas = plan["predicted_joint_sigma_deg"][:len(errors)]
    assert all(s is not None for s in sigmas), sigmas
    bounded = {j for j, s in enumerate(sigmas) if s > plan["target_sigma_deg"]}
    assert bounded <= {0, 5}, sigmas  # only J1 and J6 are the reference's
    assert all(e is not None and abs(e) <= 0.005 for j, e in enumerate(errors)
               if j not in bounded), errors
    assert all(w for w in document["truth"]["within_3_sigma"] if w is not None)
    assert document["push"]["status"] == "pushed" and document["verify"]["verdict"] == "PASS"
    check = document["reference_check"]
    assert check["moved"] is False and check["likely_cause"] is None
    assert {f["frame"] for f in check["frames"]} == {
        "stereo_target": {"tool", "target"}, "sphere_probe": {"tool", "sphere"},
        "world_point": {"world", "markers"}}[method]
    assert "reference check:" in (tmp_path / "swap" / "summary.txt").read_text()


@pytest.mark.slow
def test_a_moved_target_is_named_nothing_is_pushed_and_a_resume_drops_the_reference(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    reference, before, rig = recorded(tmp_path, "stereo_target")
    assert before["reference_check"] is None
    # the target (no error in the recording world) moved 0.5 mm, in base x and z
    moved = world("stereo_target", 4, [SWAP, *SMALL[1:5], SWAP],
                  target={"centre_error": [0.0003, 0.0, 0.0004]})
    run = tmp_path / "moved"
    code, document = calibrate(run, moved, "stereo_target", "--reference", str(reference),
                               *rig)
    capsys.readouterr()
    assert code == 5  # push refused
    check = document["reference_check"]
    assert check["moved"] is True and check["likely_cause"] == "target"
    target = next(f for f in check["frames"] if f["frame"] == "target")
    assert 0.3 <= target["translation_mm"] <= 0.6
    assert document["push"]["status"] == "refused"
    assert "the target frame moved" in document["push"]["reason"]
    assert f"hostpc calibrate --resume {run} --reference none" in document["push"]["reason"]
    # refused even with --force: the next command drops the reference, never --force
    assert document["outcome"]["next_command"] == (
        f"hostpc calibrate --resume {run} --reference none")
    refused = Journal(run).events("push_refused")[-1]
    assert refused["rule"] == "reference_moved"
    summary = (run / "summary.txt").read_text()
    assert "reference check: the target frame moved" in summary
    # the resume refits the same samples without the reference: J1 and J6 unidentifiable
    n_fit = sum(1 for line in (run / "journal.jsonl").read_text().splitlines()
                if '"phase": "fit"' in line)
    code, out, err = run_cli(capsys, "calibrate", "--resume", str(run), "--reference", "none",
                             "--no-push")
    assert code == 0, err
    resumed = json.loads((run / "result.json").read_text())
    assert resumed["reference_check"] is None
    assert set(resumed["plan"]["joints"]["not_calibrated"]) == {"J1", "J6"}
    assert not (run / "reference.json").exists()
    assert n_fit == sum(1 for line in (run / "journal.jsonl").read_text().splitlines()
                        if '"phase": "fit"' in line)  # nothing measured again


@pytest.mark.slow
def test_resume_with_known_none_refits_without_the_surveyed_target(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    run = tmp_path / "run"
    code, out, err = run_cli(capsys, "calibrate", "--robot", "sim", "--no-push", "--out",
                             str(run), "--no-report")
    assert code == 0, err
    first = json.loads((run / "result.json").read_text())
    assert first["known"] == ["target"] and "J1" in first["plan"]["joints"]["from_measurements"]
    code, out, err = run_cli(capsys, "calibrate", "--resume", str(run), "--known", "none",
                             "--no-push")
    assert code == 0, err
    assert "resume with known frames: none" in err
    resumed = json.loads((run / "result.json").read_text())
    assert resumed["known"] == [] and "J1" in resumed["plan"]["joints"]["not_calibrated"]
    assert resumed["truth"]["joint_offsets_error_deg"][0] is None
    assert json.loads((run / "run.json").read_text())["cell"]["known"] == []


def test_a_user_prior_on_a_frame_that_resolves_a_joint_is_the_measurements_not_a_reference(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """`--prior tool.x=...` (the --help's example) resolves J6 from the measurements: the run
    gets past the plan and says so (joint_coverage: bare with the user's constraints, full
    with the reference's as well; a reference alone still resolves J6)."""
    from hostpc.calibrate.reference import load_reference
    from hostpc.calibrate.run_header import read_run_header
    from hostpc.calibrate.run_reference import joint_coverage
    from hostpc.methods import method_class
    from hostpc.methods.cell import cell_from_dict

    out = tmp_path / "prior"
    code = main(["calibrate", "--robot", "sim", "--prior", "tool.x=0.045+-0.0005m",
                 "--out", str(out), "--no-report"])
    err = capsys.readouterr().err
    assert "Traceback" not in err and code in (0, 5, 7), err[-2000:]
    document = json.loads((out / "result.json").read_text())
    assert document["outcome"]["headline"]  # whatever the verdict, it is stated
    joints = document["plan"]["joints"]
    assert "J6" in joints["from_measurements"] and joints["from_reference"] == []
    assert "J6 with --hold/--prior on tool" in joints["text"]

    # the same plan, straight through joint_coverage, with and without a reference
    record = tmp_path / "record"
    assert main(["calibrate", "--robot", "sim", "--out", str(record), "--no-report"]) == 0
    assert main(["reference", "record", "--run", str(record), "--out",
                 str(tmp_path / "ref.json")]) == 0
    reference = load_reference(tmp_path / "ref.json")
    header = read_run_header(Journal(record))
    assert header.plan is not None
    cell = cell_from_dict(header.cell, header.settings.plugins)
    settings = header.settings
    method = method_class(settings.method, settings.plugins)(settings, cell, record)
    asyncio.run(method.prepare(None, NullProgress()))  # type: ignore[arg-type]  # rig.json
    plan = header.plan
    assert joint_coverage(method, plan, settings, cell, reference)["from_reference"] == ["J6"]
    prior = dataclasses.replace(settings, priors=("tool.x=0.045+-0.0005m",))
    coverage = joint_coverage(method, plan, prior, cell, None)  # AttributeError on the old
    assert coverage["from_reference"] == [] and coverage["resolved_by_reference"] == []
    assert coverage["from_measurements"] == ["J1", "J2", "J3", "J4", "J5", "J6"]
    assert "J6 with --hold/--prior on tool" in coverage["text"]
    held = dataclasses.replace(settings, hold=("tool.rz",))
    coverage = joint_coverage(method, plan, held, cell, None)
    assert coverage["from_reference"] == [] and coverage["resolved_by_reference"] == []
    assert "J6" in coverage["from_measurements"] and coverage["not_calibrated"] == {}
    assert "J6 with --hold/--prior on tool" in coverage["text"]
