"""docs/measurement-models.md is true: its example model keeps the contract as a plugin
file, its dataset file loads with it, and the fit runs on it."""

from __future__ import annotations

import json
import re
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from hostpc.dataset import dataset_from_dict
from hostpc.errors import DatasetError
from hostpc.fitting import solve
from hostpc.model.measurements import measurement_models
from hostpc.model.measurements.predict import predict
from hostpc.model.problem import build_problem
from tests.hostpc.measurement_contract import check_model

DOC = Path(__file__).resolve().parents[2] / "docs" / "measurement-models.md"


def blocks(language: str) -> list[str]:
    return re.findall(rf"```{language}\n(.*?)```", DOC.read_text(encoding="utf-8"), re.S)


@pytest.fixture()
def plugin(tmp_path: Path) -> str:
    (source,) = [b for b in blocks("python") if "(MeasurementModel):" in b]
    path = tmp_path / "plane_contact.py"
    path.write_text(source)
    return str(path)


def test_doc_model_keeps_the_contract(plugin: str, tmp_path: Path) -> None:
    check_model(measurement_models([plugin])["plane_contact"], tmp_path, plugins=[plugin])


def test_doc_dataset_loads_with_the_plugin_only(plugin: str) -> None:
    (text,) = blocks("json")
    dataset = dataset_from_dict(json.loads(text), plugins=[plugin])
    assert dataset.method == "plane_contact"
    assert dataset.samples.fields["distance"][0] == pytest.approx(0.003)
    assert np.allclose(dataset.frames["plane"], [0.0, 0.0, -0.3])
    with pytest.raises(DatasetError, match="unknown method 'plane_contact'"):
        dataset_from_dict(json.loads(text))
    broken = json.loads(text)
    broken["samples"][0]["distance"] = "far"
    with pytest.raises(DatasetError, match=r"samples\[0\]\.distance"):
        dataset_from_dict(broken, plugins=[plugin])
    del broken["samples"][0]["distance"]
    with pytest.raises(DatasetError, match=r"samples\[0\]\.distance: required field missing"):
        dataset_from_dict(broken, plugins=[plugin])


def test_doc_model_fit_names_what_one_plate_cannot_identify(plugin: str) -> None:
    dataset = measurement_models([plugin])["plane_contact"].example(np.random.default_rng(1))
    problem = build_problem(dataset, plugins=[plugin])
    truth = np.zeros(problem.layout.size)
    truth[problem.layout.index("joint_offsets.q3")] = 1e-3
    clean, _ = predict(problem, truth, jacobian=False)
    result = solve(replace(problem, measured=clean), cv_folds=0)
    assert result.converged and result.unidentifiable
    assert all(d.description for d in result.unidentifiable)


def test_doc_commands_fit_and_diagnose_with_the_plugin(plugin: str, tmp_path: Path,
                                                       capsys: pytest.CaptureFixture[str]) -> None:
    """The doc's two commands run: `hostpc fit` and `hostpc diagnose --ladder` with --plugin
    (diagnose once failed naming the default model of a plugin's method)."""
    from hostpc.cli.main import main
    from hostpc.dataset import save_dataset

    dataset = measurement_models([plugin])["plane_contact"].example(np.random.default_rng(1))
    plate = tmp_path / "plate.json"
    save_dataset(dataset, plate, plugins=[plugin])
    assert main(["fit", str(plate), "--plugin", plugin]) == 0
    assert main(["diagnose", str(plate), "--plugin", plugin, "--ladder"]) in (0, 1)
    out = capsys.readouterr().out
    assert "--plugin" in out  # the suggested commands carry the plugin
