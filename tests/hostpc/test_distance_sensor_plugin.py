"""A measurement model that lives in the tests only (distance_sensor_plugin.py, loaded with
--plugin): it keeps the contract, and `hostpc fit` / `hostpc diagnose` work on its data."""

from __future__ import annotations

import json
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

from hostpc.dataset import save_dataset
from hostpc.model.measurements import measurement_models
from hostpc.model.measurements.predict import predict
from hostpc.model.problem import build_problem
from tests.hostpc.measurement_contract import check_model

PLUGIN = str(Path(__file__).with_name("distance_sensor_plugin.py"))
ROOT = Path(__file__).resolve().parents[2]
TRUTH = {"joint_offsets.q2": 0.0012, "joint_offsets.q3": -0.0008, "joint_offsets.q4": 0.0005,
         "tool.z": 0.002, "anchor.x": -0.001}


def test_the_plugin_model_keeps_the_contract(tmp_path: Path) -> None:
    models = measurement_models([PLUGIN])
    assert "draw_wire" in models and "draw_wire" not in measurement_models()
    check_model(models["draw_wire"], tmp_path, plugins=[PLUGIN])


def synthetic_file(tmp_path: Path) -> Path:
    """A draw_wire dataset measured at TRUTH with 20 um noise."""
    cls = measurement_models([PLUGIN])["draw_wire"]
    dataset = cls.example(np.random.default_rng(3))
    problem = build_problem(dataset, plugins=[PLUGIN])
    x = np.array([TRUTH.get(name, 0.0) for name in problem.layout.names])
    clean, _ = predict(problem, x, jacobian=False)
    noise = np.random.default_rng(4).normal(0.0, 2e-5, clean.shape[0])
    fields = dict(dataset.samples.fields, distance=clean[:, 0] + noise)
    noisy = dataset.with_samples(replace(dataset.samples, fields=fields))
    path = tmp_path / "wire.json"
    save_dataset(noisy, path, plugins=[PLUGIN])
    return path


def run(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "hostpc.cli.main", *args], cwd=ROOT,
                          capture_output=True, text=True, timeout=300)


def test_fit_and_diagnose_on_the_command_line(tmp_path: Path) -> None:
    path = synthetic_file(tmp_path)
    fitted = run("fit", str(path), "--plugin", PLUGIN, "--json")
    assert fitted.returncode == 0, fitted.stderr
    result = json.loads(fitted.stdout)
    assert result["method"] == "draw_wire" and result["converged"]
    for name in ("joint_offsets.q2", "joint_offsets.q3", "joint_offsets.q4"):
        estimate = result["parameters"][name]
        assert abs(estimate["value"] - TRUTH[name]) < 5 * estimate["std"] + 1e-6, name
    diagnosed = run("diagnose", str(path), "--plugin", PLUGIN, "--json")
    assert diagnosed.returncode == 0, diagnosed.stderr
    assert json.loads(diagnosed.stdout)["fit"]["method"] == "draw_wire"
    unknown = run("fit", str(path))
    assert unknown.returncode != 0 and "draw_wire" in unknown.stderr
    assert "Traceback" not in unknown.stderr
