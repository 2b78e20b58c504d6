"""A laser-tracker CSV read in the wrong unit (review B): metres read as mm must not end in
an "adequate" verdict and a robot shrunk to a thousandth (the import warns, the verdict says
chi2/dof is far below its band and the geometry is implausible, `--effects auto` does not
choose it); radians read as degrees get a warning that names the joint unit. Correct data
gets no new warning and stays adequate."""

from __future__ import annotations

import dataclasses
import json
import shlex
from pathlib import Path

import numpy as np
import pytest

from hostpc.cli.main import main
from hostpc.diagnostics import diagnose
from hostpc.kinematics import get_robot, pose_to_transform
from hostpc.kinematics.poses import forward
from tests.hostpc.diagnose_support import hidden_dataset
from tests.hostpc.realdata import DATA, fit_json

NOISE_M = 2e-5
MARKERS = np.array([[0.05, 0.0, 0.03], [-0.03, 0.045, 0.03], [-0.03, -0.045, 0.05]])
COLUMNS = "q=J1:J6,marker.a=x1:z1,marker.b=x2:z2,marker.c=x3:z3"
IMPORT = ["--method", "world_point", "--robot", "ur5e", "--columns", COLUMNS]
SLIP = "warning: the measured points spread"


def _tracker_csv(path: Path, n_poses: int = 30, seed: int = 1) -> Path:
    """A UR5e with small zero offsets carrying three reflectors, seen by a tracker 1.5 m away
    (m, rad; 20 um noise): one row per pose, the joints then each reflector's x, y, z."""
    rng = np.random.default_rng(seed)
    chain = get_robot("ur5e")
    offsets = np.deg2rad([0.0, 0.15, -0.10, 0.12, -0.08, 0.0])
    T_tracker_base = np.linalg.inv(pose_to_transform([1.5, -0.4, 0.2], [0.01, -0.02, 0.5]))
    low = np.array([-2.5, -2.2, 0.3, -3.0, -2.5, -3.0])
    high = np.array([2.5, -0.6, 2.3, 3.0, 2.5, 3.0])
    q = low + (high - low) * rng.random((n_poses, 6))
    T_base_flange = forward(chain, q + offsets).T_base_flange
    rows = []
    for k in range(n_poses):
        points = [(T_tracker_base @ T_base_flange[k] @ np.r_[m, 1.0])[:3]
                  + rng.normal(0.0, NOISE_M, 3) for m in MARKERS]
        rows.append(",".join(f"{v:.9f}" for v in np.r_[q[k], *points]))
    path.write_text("J1,J2,J3,J4,J5,J6,x1,y1,z1,x2,y2,z2,x3,y3,z3\n" + "\n".join(rows) + "\n")
    return path


def _import(capsys: pytest.CaptureFixture[str], csv: Path, out: Path, *options: str) -> str:
    """`hostpc import CSV ... OPTIONS -o OUT`; its stderr."""
    capsys.readouterr()
    assert main(["import", str(csv), *IMPORT, *options, "-o", str(out)]) == 0
    return capsys.readouterr().err


def test_metres_read_as_mm_get_a_warning_with_the_corrected_command(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    csv = _tracker_csv(tmp_path / "tracker.csv")
    err = _import(capsys, csv, tmp_path / "mm.json", "--sigma", "0.02", "--length-unit", "mm")
    assert SLIP in err and "read with --length-unit mm" in err
    assert "the lengths look like m, not mm" in err
    command = err.strip().rsplit(": hostpc ", 1)[1]
    words = shlex.split(command)
    assert words[:2] == ["import", str(csv)]
    # the same noise in the new unit: 0.02 mm is 2e-05 m
    assert words[words.index("--length-unit") + 1] == "m"
    assert words[words.index("--sigma") + 1] == "2e-05"
    capsys.readouterr()
    assert main(words) == 0  # the corrected command as printed: no warning
    assert SLIP not in capsys.readouterr().err


def test_radians_read_as_degrees_get_a_warning_that_names_the_joint_unit(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    csv = _tracker_csv(tmp_path / "tracker.csv")
    err = _import(capsys, csv, tmp_path / "deg.json", "--sigma", "2e-5", "--joint-unit", "deg")
    assert SLIP in err
    assert "every revolute joint spans under" in err and "deg with --joint-unit deg" in err
    assert "the joint values look like rad, not deg" in err
    assert "--joint-unit rad" in err.rsplit(": hostpc ", 1)[1]


def test_metres_read_as_mm_are_never_adequate_nor_chosen(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The review's case: a robot fitted to points a thousand times too close shrinks to a
    thousandth with chi2/dof ~1e-6; neither counts as adequate, and auto does not pick it."""
    csv = _tracker_csv(tmp_path / "tracker.csv")
    dataset = tmp_path / "mm.json"
    _import(capsys, csv, dataset, "--sigma", "0.02", "--length-unit", "mm")
    diagnosis = diagnose(dataset, ladder=True, interactions=False)
    assert diagnosis.ladder is not None
    assert not any(step.adequate for step in diagnosis.ladder)
    geometry = [s for s in diagnosis.ladder if "geometry" in s.effects]
    assert geometry, "the ladder adds geometry (a shrunken robot fits the points)"
    reasons = " ".join(geometry[0].check.adequacy.reasons)
    assert "far below its band" in reasons and "the fitted geometry is implausible" in reasons
    assert "geometry.a2" in reasons
    choice = fit_json(dataset, "auto")["model_choice"]
    assert choice["chosen"] != "offsets + geometry"
    row = next(m for m in choice["models"] if m["name"] == "offsets + geometry")
    assert "implausible geometry" in row["note"]


def test_correct_units_warn_nothing_and_stay_adequate(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    csv = _tracker_csv(tmp_path / "tracker.csv")
    dataset = tmp_path / "si.json"
    assert SLIP not in _import(capsys, csv, dataset, "--sigma", "2e-5")
    diagnosis = diagnose(dataset, interactions=False)
    assert diagnosis.adequate, diagnosis.check.adequacy.reasons


def test_a_stated_noise_far_too_large_is_not_adequate() -> None:
    """Covariances 4x (sigma 2x) too large stay adequate (pessimistic); 10^4x (sigma 100x):
    far below the band, not adequate, with the next step."""
    synthetic = hidden_dataset({}, seed=4, n_samples=60)
    samples = synthetic.dataset.samples
    verdicts = {}
    for scale in (4.0, 1e4):
        scaled = dataclasses.replace(synthetic.dataset, samples=dataclasses.replace(
            samples, cov=samples.cov * scale))
        verdicts[scale] = diagnose(scaled, cv_folds=0, rank_cv_folds=0, interactions=False)
    assert verdicts[4.0].adequate
    far = verdicts[1e4].check.adequacy
    assert not far.adequate and far.chi2_ok  # the push's rule (upper tail) is unchanged
    assert "far below its band" in far.reasons[0] and "next:" in far.reasons[0]


@pytest.mark.parametrize("csv, options", [
    ("figaroh_ur10e_calibration.csv",
     ["--method", "world_pose", "--robot", "ur10e", "--sigma", "0.001", "--columns",
      "q=shoulder_pan_joint:wrist_3_joint,x=x1,y=y1,z=z1,roll=phix1,pitch=phiy1,yaw=phiz1"]),
    ("figaroh_tiago_mocap_calibration.csv",
     ["--method", "world_point", "--robot", str(DATA / "tiago_arm.urdf"), "--base-link",
      "torso_fixed_link", "--tip-link", "arm_7_link", "--sigma", "0.001", "--columns",
      "q=torso_lift_joint:arm_7_joint,marker.a=x1:z1,marker.b=x2:z2,marker.c=x3:z3"]),
    ("figaroh_tiago_mocap_2021-11-26.csv",
     ["--method", "world_point", "--robot", str(DATA / "tiago_arm.urdf"), "--base-link",
      "torso_fixed_link", "--tip-link", "arm_7_link", "--sigma", "0.001", "--columns",
      "q=torso_lift_joint:arm_7_joint,marker.a=x1:z1,marker.b=x2:z2,marker.c=x3:z3"]),
    ("figaroh_talos_left_arm_mocap.csv",
     ["--method", "world_point", "--robot", str(DATA / "talos_left_arm.urdf"), "--base-link",
      "base_link", "--tip-link", "arm_left_7_link", "--sigma", "0.001", "--columns",
      "q=torso_1_joint:arm_left_7_joint,x=x1,y=y1,z=z1,t=t"]),
])
def test_real_sets_get_no_unit_warning(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                       csv: str, options: list[str]) -> None:
    capsys.readouterr()
    assert main(["import", str(DATA / csv), *options, "-o", str(tmp_path / "d.json")]) == 0
    assert SLIP not in capsys.readouterr().err
    document = json.loads((tmp_path / "d.json").read_text())
    assert document["samples"]


def test_fit_says_the_slip(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """`hostpc fit`: the units hint of a fit 100x above the stated noise names the joint
    values that look too small; +geometry on metres read as mm is far below its band and
    its geometry implausible (before: "converged: yes")."""
    csv = _tracker_csv(tmp_path / "tracker.csv")
    deg, mm = tmp_path / "deg.json", tmp_path / "mm.json"
    _import(capsys, csv, deg, "--sigma", "2e-5", "--joint-unit", "deg")
    _import(capsys, csv, mm, "--sigma", "0.02", "--length-unit", "mm")
    assert main(["fit", str(deg), "--cv-folds", "0"]) == 0
    line = capsys.readouterr().out.splitlines()[1]
    assert "every revolute joint spans under" in line and "(rad read as deg?)" in line
    assert main(["fit", str(mm), "--effects", "+geometry", "--cv-folds", "0"]) == 0
    out = capsys.readouterr().out
    assert "is far below its band" in out.splitlines()[1]
    assert "warning: the fitted geometry is implausible: geometry.a2" in out


def test_diagnose_names_the_unit_slip_before_any_effect(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Radians imported as degrees look like an encoder scale to the diagnosis: its first
    advice names the unit slip, as `hostpc import` and `hostpc fit` do (text and --json);
    correct units get no such advice."""
    csv = _tracker_csv(tmp_path / "tracker.csv")
    deg, si = tmp_path / "deg.json", tmp_path / "si.json"
    _import(capsys, csv, deg, "--sigma", "2e-5", "--joint-unit", "deg")
    _import(capsys, csv, si, "--sigma", "2e-5")
    main(["diagnose", str(deg), "--cv-folds", "0", "--json"])
    advice = json.loads(capsys.readouterr().out)["advice"]
    assert advice[0].startswith("Check the units first: the measured points spread"), advice
    assert "every revolute joint spans under" in advice[0] and "(rad read as deg?)" in advice[0]
    assert "encoder_scale" not in advice[0]
    main(["diagnose", str(deg), "--cv-folds", "0"])
    text = capsys.readouterr().out
    assert text.split("advice:\n", 1)[1].startswith("  - Check the units first:"), text
    main(["diagnose", str(si), "--cv-folds", "0", "--json"])
    assert not any("Check the units" in a for a in json.loads(capsys.readouterr().out)["advice"])
