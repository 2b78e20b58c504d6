"""A measurement kind added from one folder (tests/kinds_example/tracker_range, loaded with
``--plugin FOLDER``) runs ``hostpc fit``, ``hostpc diagnose --ladder`` and ``hostpc
calibrate --robot sim`` end to end. No existing file knows it: it registers itself through
its descriptor (``KIND``), and it measures with the stub's existing laser tracker
(``measure_tracker``), so no stub change either."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from hostpc.dataset import save_dataset
from hostpc.model.measurements import measurement_models
from hostpc.model.measurements.predict import predict
from hostpc.model.problem import build_problem
from tests.hostpc.measurement_contract import check_model
from tests.integration.test_calibrate_sim import run_cli

KIND = str(Path(__file__).resolve().parents[1] / "kinds_example" / "tracker_range")
TRUTH = {"joint_offsets.q2": 0.0012, "joint_offsets.q3": -0.0008, "joint_offsets.q4": 0.0005,
         "joint_offsets.q5": -0.0006}


def synthetic_file(tmp_path: Path, kind: str = KIND, name: str = "tracker_range",
                   field: str = "distance", sigma: float = 8e-6,
                   truth: dict[str, float] = TRUTH) -> Path:
    """A dataset of the folder kind `kind` (its model's example poses) measured at `truth`
    with noise `sigma` in its scalar `field`; both frames known (a surveyed instrument and a
    pinned nest), as the simulated cell says. Default: tracker_range, the tracker's 8 um."""
    dataset = measurement_models([kind])[name].example(np.random.default_rng(3))
    dataset = replace(dataset, known=("tool", "anchor"))
    problem = build_problem(dataset, plugins=[kind])
    x = np.array([truth.get(p, 0.0) for p in problem.layout.names])
    clean, _ = predict(problem, x, jacobian=False)
    noise = np.random.default_rng(4).normal(0.0, sigma, clean.shape[0])
    fields = dict(dataset.samples.fields, **{field: clean[:, 0] + noise})
    path = tmp_path / f"{name}.json"
    save_dataset(dataset.with_samples(replace(dataset.samples, fields=fields)), path,
                 plugins=[kind])
    return path


def test_the_folder_kind_keeps_the_measurement_contract(tmp_path: Path) -> None:
    models = measurement_models([KIND])
    assert "tracker_range" in models and "tracker_range" not in measurement_models()
    check_model(models["tracker_range"], tmp_path, plugins=[KIND])


def test_fit_of_the_folder_kind(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = synthetic_file(tmp_path)
    code, stdout, stderr = run_cli(capsys, "fit", str(path), "--plugin", KIND, "--json")
    assert code == 0, stderr
    result = json.loads(stdout)
    assert result["method"] == "tracker_range" and result["converged"]
    for name, true in TRUTH.items():
        estimate = result["parameters"][name]
        assert abs(estimate["value"] - true) < 5 * estimate["std"] + 1e-6, name
    code, _, stderr = run_cli(capsys, "fit", str(path))
    assert code != 0 and "tracker_range" in stderr and "Traceback" not in stderr


def test_diagnose_ladder_of_the_folder_kind(tmp_path: Path,
                                            capsys: pytest.CaptureFixture[str]) -> None:
    path = synthetic_file(tmp_path)
    code, stdout, stderr = run_cli(capsys, "diagnose", "--ladder", str(path), "--plugin", KIND)
    assert code == 0, stderr
    assert "ladder:" in stdout and "adequate" in stdout


def test_calibrate_sim_with_the_folder_kind(tmp_path: Path,
                                            capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "run"
    code, stdout, stderr = run_cli(capsys, "calibrate", "--robot", "sim", "--plugin", KIND,
                                   "--method", "tracker_range", "--poses", "20",
                                   "--verify-poses", "4", "--out", str(out), "--json",
                                   "--no-report")
    assert code == 0, stderr
    document = json.loads(stdout)
    assert document["method"] == "tracker_range"
    assert document["known"] == ["tool", "anchor"]  # its descriptor's simulated cell
    errors = document["truth"]["joint_offsets_error_deg"]
    assert all(e is not None and abs(e) <= 0.01 for e in errors), errors
    assert document["push"]["status"] == "pushed"
    assert document["verify"]["passed"] is True
    code, stdout, _ = run_cli(capsys, "fit", str(out / "dataset.json"), "--plugin", KIND)
    assert code == 0
