"""A robust-loss fit is judged on the samples its loss keeps (hostpc.diagnostics.robust_kept):
one pose read 0.002 rad off on J3, measured with three reflectors, is three outliers; the
cauchy fit recovers the truth, says its chi2/dof over the other samples, names the pose it
set aside, and `hostpc push` takes it. A linear fit of the same data is judged as before,
and its refused push names the dataset its FIT.json names."""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from hostpc.calibrate.offline_push import load_saved_fit
from hostpc.calibrate.push import adequacy_chi2, plan_push
from hostpc.cli.main import main
from hostpc.dataset import save_dataset
from tests.hostpc.diagnose_support import hidden_world_point

BAD_POSE = 11  # samples 33, 34, 35
BAD_J3 = 0.002  # rad added to the J3 reading of that pose


@pytest.fixture(scope="module")
def bad_pose(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, float]]:
    synthetic = hidden_world_point({}, seed=4, n_samples=120, markers_per_pose=3)
    dataset = synthetic.dataset
    q = np.array(dataset.samples.q, float)
    q[3 * BAD_POSE:3 * BAD_POSE + 3, 2] += BAD_J3  # the reading, not the arm, is off
    dataset = dataclasses.replace(dataset, samples=dataclasses.replace(dataset.samples, q=q))
    path = tmp_path_factory.mktemp("badpose") / "badpose.json"
    save_dataset(dataset, path)
    return path, synthetic.truth


@pytest.fixture(scope="module")
def controller(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Any]:
    """A controller-stub (subprocess, 127.0.0.1) of the default simulated UR5e."""
    from hostpc.robots.simulator import SimulatedController, default_sim_scenario

    with SimulatedController(default_sim_scenario(), tmp_path_factory.mktemp("stub")) as sim:
        yield sim


def _fit(capsys: pytest.CaptureFixture[str], path: Path, *options: str) -> tuple[str, Any]:
    assert main(["fit", str(path), "--cv-folds", "0", *options]) == 0
    text = capsys.readouterr().out
    assert main(["fit", str(path), "--cv-folds", "0", "--json", *options]) == 0
    return text, json.loads(capsys.readouterr().out)


def test_a_cauchy_fit_is_judged_on_the_samples_it_keeps(
        bad_pose: tuple[Path, dict[str, float]], capsys: pytest.CaptureFixture[str],
        tmp_path: Path) -> None:
    path, truth = bad_pose
    text, document = _fit(capsys, path, "--loss", "cauchy")
    q3 = document["parameters"]["joint_offsets.q3"]
    assert abs(q3["value"] - truth["joint_offsets.q3"]) < 4 * q3["std"] < 1e-4
    assert document["chi2_dof"] > 5  # every sample: the bad pose dominates
    adequacy = document["model_adequacy"]
    kept = adequacy["kept_samples"]
    assert kept["left_out"] == [33, 34, 35] and kept["n_kept"] == 117
    assert kept["max_weight"] < 0.01 and kept["dof"] == document["dof"] - 9
    assert adequacy["explains_data"] is True and adequacy["next"] is None
    assert adequacy["chi2_dof"] == kept["chi2_dof"] < adequacy["chi2_dof_upper"]
    assert "converged: yes" in text and "does not explain" not in text
    assert ("over the 117 samples the cauchy loss keeps; pose #11 (samples #33-#35, every "
            "sample of it) down-weighted below") in text
    assert "x sqrt(chi2/dof)" not in text  # no scaled sigmas for a model that explains

    fit_file = tmp_path / "fit.json"
    fit_file.write_text(json.dumps(document))
    saved = load_saved_fit(fit_file)
    assert saved.kept_samples is not None and saved.kept_samples.left_out == (33, 34, 35)
    tested = adequacy_chi2(saved)  # type: ignore[arg-type]
    assert tested.kept is not None and tested.dof == kept["dof"]
    assert plan_push(saved, np.zeros(6)).refused is None  # type: ignore[arg-type]


def test_a_linear_fit_is_judged_on_every_sample(
        bad_pose: tuple[Path, dict[str, float]], capsys: pytest.CaptureFixture[str]) -> None:
    path, _ = bad_pose
    text, document = _fit(capsys, path)
    adequacy = document["model_adequacy"]
    assert "kept_samples" not in adequacy and adequacy["explains_data"] is False
    assert adequacy["chi2_dof"] == document["chi2_dof"]
    assert "loss keeps" not in text and "does not explain the data" in text


def test_push_takes_the_cauchy_fit_and_names_the_dataset_when_it_refuses(
        bad_pose: tuple[Path, dict[str, float]], capsys: pytest.CaptureFixture[str],
        tmp_path: Path, controller: Any, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("ZEROCAL_TOKEN", controller.token)
    address = f"{controller.address.host}:{controller.address.port}"
    path, _ = bad_pose
    for loss, code in (("cauchy", 0), ("linear", 5)):
        _, document = _fit(capsys, path, "--loss", loss)
        fit_file = tmp_path / f"{loss}.json"
        fit_file.write_text(json.dumps(document))
        assert main(["push", str(fit_file), "--robot", address, "--dry-run"]) == code
        out = capsys.readouterr()
        if code:
            assert f"run `hostpc diagnose {path}`" in out.err + out.out
            assert "DATASET (the dataset" not in out.err + out.out


def test_a_hand_edited_kept_block_is_refused_in_one_line(
        bad_pose: tuple[Path, dict[str, float]], capsys: pytest.CaptureFixture[str],
        tmp_path: Path) -> None:
    path, _ = bad_pose
    _, document = _fit(capsys, path, "--loss", "cauchy")
    for field, value, message in (("dof", document["dof"], "kept_samples.dof"),
                                  ("loss", "linear", "kept_samples.loss"),
                                  ("left_out", [33, 33, 35], "kept_samples.left_out"),
                                  ("chi2", "0.5", "kept_samples.chi2")):
        edited = json.loads(json.dumps(document))
        edited["model_adequacy"]["kept_samples"][field] = value
        fit_file = tmp_path / "edited.json"
        fit_file.write_text(json.dumps(edited))
        assert main(["push", str(fit_file), "--robot", "127.0.0.1:9", "--dry-run"]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and message in err, err


def test_diagnose_names_the_pose_whose_every_sample_is_an_outlier(
        bad_pose: tuple[Path, dict[str, float]], capsys: pytest.CaptureFixture[str],
        tmp_path: Path) -> None:
    """One pose read wrong is one measurement to check, not three outliers; a single bad
    reflector of a pose stays a sample."""
    path, _ = bad_pose
    main(["diagnose", str(path), "--cv-folds", "0"])
    text = capsys.readouterr().out
    assert ("are outliers, all of pose #11 (samples #33-#35, every sample of it): check that "
            "pose's measurement, or fit with --loss cauchy") in text
    assert "; pose #11 (samples #33-#35, every sample of it); left out below" in text
    main(["diagnose", str(path), "--cv-folds", "0", "--json"])  # the same grouping
    report = json.loads(capsys.readouterr().out)
    assert report["outlier_poses"] == [{"pose": 11, "samples": [33, 34, 35]}]
    assert sorted(o["sample"] for o in report["outliers"]) == [33, 34, 35]  # kept as were

    document = json.loads(path.read_text())
    for sample in document["samples"][3 * BAD_POSE:3 * BAD_POSE + 3]:
        sample["q"][2] -= BAD_J3  # the pose read right again ...
    document["samples"][3 * BAD_POSE + 1]["p"][0] += 1e-3  # ... one reflector 1 mm off
    one = tmp_path / "one.json"
    one.write_text(json.dumps(document))
    main(["diagnose", str(one), "--cv-folds", "0"])
    text = capsys.readouterr().out
    assert "Sample #34 (" in text and "is an outlier: check that measurement" in text
    assert "every sample of it" not in text
    main(["diagnose", str(one), "--cv-folds", "0", "--json"])
    assert json.loads(capsys.readouterr().out)["outlier_poses"] == []
