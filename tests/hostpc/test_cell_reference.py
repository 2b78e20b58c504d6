"""Cell references offline: correlated prior blocks, the file's validation, recording from a
fit, and the check that names a moved frame (hostpc.calibrate.reference, reference_check,
hostpc.fitting.priors)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from hostpc.calibrate.reference import (
    REFERENCE_FORMAT,
    frame_priors,
    load_reference,
    reference_from_dict,
    reference_from_fit,
)
from hostpc.calibrate.reference_check import check_reference
from hostpc.cli.main import main
from hostpc.errors import InputError
from hostpc.fitting import fit
from hostpc.fitting.priors import constraints_for, with_prior_blocks
from hostpc.synthesize import synthesize_stereo_target

TRUTH = {"joint_offsets.q1": 0.0, "joint_offsets.q2": 0.001, "joint_offsets.q3": -0.0008,
         "joint_offsets.q4": 0.0006, "joint_offsets.q5": -0.0004, "joint_offsets.q6": 0.0,
         "tool.x": 8e-4, "tool.y": -5e-4, "tool.z": 6e-4, "tool.rx": 0.002, "tool.ry": -0.001,
         "tool.rz": 0.003, "target.x": 7e-4, "target.y": -1.1e-3, "target.z": 4e-4}


def test_a_prior_block_is_whitened_by_its_covariance() -> None:
    covariance = np.array([[4.0, 1.0], [1.0, 2.0]]) * 1e-8
    block = {"names": ["tool.x", "tool.y"], "value": [1e-4, -2e-4],
             "covariance": covariance.tolist()}
    constraints = constraints_for({"prior_blocks": [block]}, ("tool.x", "tool.y", "q"),
                                  ("m", "m", "rad"))
    assert constraints is not None
    x = np.array([3e-4, 1e-4, 0.5])
    r = constraints.residuals(x)
    d = x[:2] - np.array([1e-4, -2e-4])
    assert r @ r == pytest.approx(d @ np.linalg.solve(covariance, d))
    J = constraints.jacobian(3)
    assert np.allclose(J[:, :2] @ d, r) and np.all(J[:, 2] == 0.0)
    with pytest.raises(InputError, match="not positive definite"):
        constraints_for({"prior_blocks": [{**block, "covariance": [[1, 2], [2, 1]]}]},
                        ("tool.x", "tool.y"), ("m", "m"))
    with pytest.raises(InputError, match="given twice"):
        constraints_for({"prior_blocks": [block], "priors": ["tool.x=0+-1mm"]},
                        ("tool.x", "tool.y"), ("m", "m"))


def _reference() -> tuple[dict[str, object], object]:
    recording = fit(synthesize_stereo_target(TRUTH, n_samples=24, seed=1,
                                             noise_scale=0.25).dataset, cv_folds=0)
    reference = reference_from_fit(recording, robot_serial="SN-1", cell={},
                                   source_run="r", software="t")
    return reference.to_dict(), reference


def test_a_motor_swap_is_recovered_and_a_moved_target_named() -> None:
    document, _ = _reference()
    reference = reference_from_dict(json.loads(json.dumps(document)), "test")
    assert {f.name for f in reference.frames} == {"tool", "target"}
    for moved in (0.0, 5e-4):
        truth = {**TRUTH, "joint_offsets.q1": math.radians(2), "joint_offsets.q6":
                 math.radians(2), "target.z": TRUTH["target.z"] + moved}
        dataset = synthesize_stereo_target(truth, n_samples=24, seed=2,
                                           noise_scale=0.25).dataset
        without = fit(dataset, cv_folds=0)
        assert {d.fixed for d in without.unidentifiable} == {"joint_offsets.q1",
                                                            "joint_offsets.q6"}
        priors = frame_priors(reference, dataset, ("tool", "target"))
        result = fit(with_prior_blocks(dataset, [p.block() for p in priors]), cv_folds=0)
        assert not result.unidentifiable
        check = check_reference(result, priors)
        if moved:
            assert check.likely_cause == "target"
            assert check.cause().translation_mm == pytest.approx(0.5, abs=0.1)  # type: ignore[union-attr]
        else:
            assert check.likely_cause is None
            for j in (1, 6):
                error = result.value(f"joint_offsets.q{j}") - truth[f"joint_offsets.q{j}"]
                assert abs(math.degrees(error)) < 0.02


@pytest.mark.parametrize(("edit", "message"), [
    (lambda d: d.update(format="zerocal-cell-reference/9"), "is not 'zerocal-cell-reference/1'"),
    (lambda d: d["frames"]["target"].update(covariance=[[1.0]]), "3x3 covariance"),
    (lambda d: d["frames"]["target"].update(delta=[1e9, 0, 0]), "physical range"),
    (lambda d: d.pop("frames"), "'frames' missing"),
])
def test_a_bad_reference_file_is_one_line_and_exit_2(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], edit: object,
        message: str) -> None:
    document, _ = _reference()
    assert document["format"] == REFERENCE_FORMAT
    edit(document)  # type: ignore[operator]
    path = tmp_path / "ref.json"
    path.write_text(json.dumps(document))
    with pytest.raises(InputError, match=message):
        load_reference(path)
    assert main(["reference", "show", str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and message.split("'")[0] in err


def test_a_reference_of_another_method_is_refused_before_connecting(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    document, _ = _reference()
    document["method"] = "sphere_probe"
    path = tmp_path / "ref.json"
    path.write_text(json.dumps(document))
    out = tmp_path / "run"
    code = main(["calibrate", "--robot", "127.0.0.1:9", "--reference", str(path),
                 "--out", str(out)])
    assert code == 2 and not out.exists()
    err = capsys.readouterr().err
    assert "recorded with --method sphere_probe" in err and "hostpc reference record" in err
    shown = tmp_path / "ok.json"
    shown.write_text(json.dumps(_reference()[0]))
    assert main(["reference", "show", str(shown)]) == 0
    assert "target:" in capsys.readouterr().out


def test_recording_names_the_zeros_it_takes_as_good() -> None:
    from hostpc.calibrate.run_result import RunResult
    from hostpc.cli.reference import _zeros_taken_as_good

    result = RunResult.from_dict({
        "run_dir": "runs/first", "acquisition": {"n_planned": 0, "n_measured": 0}, "fit": {},
        "offsets": {"joints": [{"joint": 6, "old_deg": 0.0, "new_deg": 0.0, "pushed": False},
                               {"joint": 2, "old_deg": 0.0, "new_deg": 0.1, "pushed": True}]},
        "outcome": {"joints": [
            {"joint": 2, "status": "calibrated"},
            {"joint": 6, "status": "not_calibrated",
             "reason": "unidentifiable with the tool frame estimated"}]}})
    lines = _zeros_taken_as_good(result, Path("runs/copy"))  # the --run given, not run_dir
    assert len(lines) == 1 and lines[0].startswith("note: J6 was not calibrated by runs/copy")
    assert "+0.00000 deg" in lines[0] and "as good" in lines[0]


def test_a_frames_distance_from_its_nominal_is_its_largest_point_move_and_its_turn() -> None:
    from hostpc.calibrate.reference import ReferenceFrame

    pose = ReferenceFrame("target", ("x", "y", "z", "rx", "ry", "rz"), np.zeros(6),
                          np.array([0.03, 0.04, 0.0, 0.0, 0.0, math.radians(2.0)]),
                          np.eye(6))
    move, turn = pose.distance_from_nominal()
    assert move == pytest.approx(0.05) and math.degrees(turn) == pytest.approx(2.0)
    markers = ReferenceFrame("markers", ("smr1.x", "smr1.y", "smr1.z", "smr2.x", "smr2.y",
                                         "smr2.z"), np.zeros(6),
                             np.array([0.001, 0.0, 0.0, 0.0, 0.0, -0.002]), np.eye(6))
    assert markers.distance_from_nominal() == pytest.approx((0.002, 0.0))
