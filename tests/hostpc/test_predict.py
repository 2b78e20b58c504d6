"""`hostpc predict` / `hostpc.predict`: a saved fit against data it never saw."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

import hostpc
from hostpc.cli.main import main
from hostpc.dataset import Dataset, save_dataset
from tests.hostpc.diagnose_support import hidden_world_point


@pytest.fixture(scope="module")
def two_days() -> tuple[Dataset, Dataset]:
    """One robot and tracker set-up, two disjoint sets of 60 poses (day 1, day 2)."""
    both = hidden_world_point({}, seed=8, n_samples=120).dataset
    day1 = both.with_samples(both.samples.subset(np.arange(60)))
    day2 = both.with_samples(both.samples.subset(np.arange(60, 120)))
    return day1, day2


def test_the_fit_predicts_the_second_day_at_the_noise(two_days) -> None:
    day1, day2 = two_days
    calibrated = hostpc.predict(hostpc.fit(day1), day2)
    nominal = hostpc.predict(hostpc.fit(day1, ["world", "markers"]), day2)
    # the zero offsets (up to 0.5 deg) are the robot's: the calibrated model predicts the
    # unseen poses near the tracker's noise (whitened ~1), the nominal one far from it
    assert calibrated.whitened_rms < 1.5
    assert nominal.whitened_rms > 10 * calibrated.whitened_rms
    assert calibrated.rms < 0.1 * nominal.rms
    assert calibrated.predicted.shape == (60, 3)
    assert np.allclose(calibrated.measured - calibrated.predicted, calibrated.residuals)


def test_a_tracker_set_up_anew_is_refitted_with_the_robot_held(two_days) -> None:
    day1, day2 = two_days
    moved = dataclasses.replace(day2.samples, p=day2.samples.p + [0.002, -0.001, 0.0])
    day2_moved = day2.with_samples(moved)
    result = hostpc.fit(day1)
    as_fitted = hostpc.predict(result, day2_moved)
    refitted = hostpc.predict(result, day2_moved, refit_frames=True)
    assert as_fitted.rms > 1.5e-3  # the 2.2 mm shift of the registration
    assert refitted.whitened_rms < 1.5
    assert set(refitted.refitted) >= {"world.x", "world.y", "world.z"}
    # the robot's parameters were held: only frame parameters were re-estimated
    assert not any(name.startswith("joint_offsets.") for name in refitted.refitted)


def test_a_second_day_registered_to_itself_is_predicted_in_the_fits_frames(two_days) -> None:
    """An import estimates the frames from the file it reads: a second day's dataset with
    the tracker moved (x +0.5 m, z -0.2 m) comes with its world frame registered to itself.
    The fit's own frames predict it ~540 mm off; only --refit-frames re-registers it."""
    from hostpc.dataset import FramePose

    day1, day2 = two_days
    shift = np.array([0.5, 0.0, -0.2])
    world = day2.pose("world")
    day2_self = dataclasses.replace(
        day2.with_samples(dataclasses.replace(day2.samples, p=day2.samples.p + shift)),
        frames={**day2.frames, "world": FramePose(xyz=world.xyz + shift, rpy=world.rpy)})
    result = hostpc.fit(day1)
    as_fitted = hostpc.predict(result, day2_self)
    assert as_fitted.rms == pytest.approx(np.linalg.norm(shift), rel=0.02)
    assert hostpc.predict(result, day2_self, refit_frames=True).whitened_rms < 1.5


def test_cli_predict_of_a_fit_with_another_robot_agrees_with_the_fit(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The real UR10e file imported as a ur5e (its frames estimated with the wrong robot),
    fitted with --robot ur10e: predicting the same samples imported as the ur10e gives the
    fit's own residual RMS (the fit's frames, not the ones the second import estimated)."""
    data = Path(__file__).parents[1] / "data" / "figaroh_ur10e_calibration.csv"
    columns = ("q=shoulder_pan_joint:wrist_3_joint,x=x1,y=y1,z=z1,roll=phix1,pitch=phiy1,"
               "yaw=phiz1")
    for robot in ("ur5e", "ur10e"):
        assert main(["import", str(data), "--method", "world_pose", "--robot", robot,
                     "--columns", columns, "-o", str(tmp_path / f"{robot}.json")]) == 0
    capsys.readouterr()
    assert main(["fit", str(tmp_path / "ur5e.json"), "--robot", "ur10e", "--json"]) == 0
    fitted = json.loads(capsys.readouterr().out)
    (tmp_path / "fit.json").write_text(json.dumps(fitted))
    assert main(["predict", str(tmp_path / "fit.json"), str(tmp_path / "ur10e.json"),
                 "--json"]) == 0
    document = json.loads(capsys.readouterr().out)
    assert document["frames"] == "fit"
    assert document["rms"] == pytest.approx(fitted["rms"], rel=1e-6)
    # the fit's next command reads the data as the fit did: with --robot ur10e
    assert fitted["model_adequacy"]["next"] == (
        f"hostpc diagnose {tmp_path / 'ur5e.json'} --robot ur10e --ladder")


def test_cli_predict_reports_the_error_and_refuses_a_mismatched_model(
        two_days, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    day1, day2 = two_days
    save_dataset(day1, tmp_path / "day1.json")
    save_dataset(day2, tmp_path / "day2.json")
    assert main(["fit", str(tmp_path / "day1.json"), "--json"]) == 0
    (tmp_path / "fit.json").write_text(capsys.readouterr().out)
    assert main(["predict", str(tmp_path / "fit.json"), str(tmp_path / "day2.json"),
                 "--json"]) == 0
    document = json.loads(capsys.readouterr().out)
    expected = hostpc.predict(hostpc.fit(day1), day2)
    assert document["n_samples"] == 60
    assert document["rms"] == pytest.approx(expected.rms, rel=1e-6)
    assert main(["predict", str(tmp_path / "fit.json"), str(tmp_path / "day2.json")]) == 0
    out = capsys.readouterr().out
    assert "position error RMS" in out and "frames: the fit's, as fitted" in out
    # a dataset with a reflector the fit never saw: one line, exit 2, names the parameter
    markers = {**day2.frames["markers"], "d": np.array([0.01, 0.02, 0.05])}
    fields = {**day2.samples.fields,
              "marker": np.where(np.arange(60) % 2 == 0, "d", day2.samples.fields["marker"])}
    other = dataclasses.replace(day2, frames={**day2.frames, "markers": markers},
                                samples=dataclasses.replace(day2.samples, fields=fields))
    save_dataset(other, tmp_path / "other.json")
    assert main(["predict", str(tmp_path / "fit.json"), str(tmp_path / "other.json")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "markers.d" in err[0] and "--refit-frames" in err[0]


def test_cli_predicts_with_a_fit_of_the_nominal_model(
        two_days, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A fit without joint offsets (the frames alone: what `--effects auto` chooses when
    nothing beats the nominal robot held out) predicts like any other; only a push needs
    joint offsets."""
    day1, day2 = two_days
    save_dataset(day1, tmp_path / "day1.json")
    save_dataset(day2, tmp_path / "day2.json")
    assert main(["fit", str(tmp_path / "day1.json"), "--effects", "world,markers",
                 "--json"]) == 0
    (tmp_path / "fit.json").write_text(capsys.readouterr().out)
    assert main(["predict", str(tmp_path / "fit.json"), str(tmp_path / "day2.json"),
                 "--json"]) == 0
    document = json.loads(capsys.readouterr().out)
    expected = hostpc.predict(hostpc.fit(day1, ["world", "markers"]), day2)
    assert document["rms"] == pytest.approx(expected.rms, rel=1e-6)
    from hostpc.calibrate.offline_push import load_saved_fit
    from hostpc.errors import InputError

    with pytest.raises(InputError, match="no joint_offsets parameters: nothing to push"):
        load_saved_fit(tmp_path / "fit.json")  # what `hostpc push` reads


def test_cli_predicts_a_fit_with_a_plugin_effect_given_the_plugin(
        two_days, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from tests.hostpc.test_plugins import WRIST_COUPLING

    day1, day2 = two_days
    plugin = tmp_path / "wrist.py"
    plugin.write_text(WRIST_COUPLING)
    save_dataset(day1, tmp_path / "day1.json")
    save_dataset(day2, tmp_path / "day2.json")
    assert main(["fit", str(tmp_path / "day1.json"), "--effects", "+wrist_coupling",
                 "--plugin", str(plugin), "--json"]) == 0
    (tmp_path / "fit.json").write_text(capsys.readouterr().out)
    assert main(["predict", str(tmp_path / "fit.json"), str(tmp_path / "day2.json"),
                 "--plugin", str(plugin), "--json"]) == 0
    document = json.loads(capsys.readouterr().out)
    result = hostpc.fit(day1, "+wrist_coupling", plugins=[plugin])
    expected = hostpc.predict(result, day2, plugins=[plugin])
    assert document["rms"] == pytest.approx(expected.rms, rel=1e-6)
    # without the plugin: one line, exit 2, saying what to give
    assert main(["predict", str(tmp_path / "fit.json"), str(tmp_path / "day2.json")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "wrist_coupling" in err[0] and "--plugin" in err[0]
