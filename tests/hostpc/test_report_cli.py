"""`hostpc report RUN`: a run's report.html written again from its files, offline;
`hostpc report DATASET.json`: the report of any dataset (docs/dataset-format.md: every
analysis command reads one); bad input is one line and exit 2."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from hostpc.cli.main import main
from hostpc.dataset import save_dataset
from tests.hostpc.diagnose_support import hidden_dataset
from tests.hostpc.report_parse import ReportReader
from tests.hostpc.test_calibration_report import document
from tests.hostpc.test_report import rendered_in_chromium


@pytest.fixture(scope="module")
def dataset_report(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """`hostpc report hidden.json --effects +joint_compliance`: its default output."""
    folder = tmp_path_factory.mktemp("dataset_report")
    save_dataset(hidden_dataset({"joint_compliance.c2": 2e-5}, seed=1, n_samples=40).dataset,
                 folder / "hidden.json")
    assert main(["report", str(folder / "hidden.json"), "--effects", "+joint_compliance"]) == 0
    return folder / "hidden.html"


def test_a_datasets_report_fits_it_with_the_model_asked_for(
        dataset_report: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    report = ReportReader(dataset_report.read_text(encoding="utf-8"))
    assert report.texts["model-verdict"].startswith("The model is")
    fitted = {row["parameter"] for row in report.rows("effect-sizes")}
    assert "joint_compliance.c2" in fitted
    # the model options choose the model; --out the file
    out = tmp_path / "linear.html"
    capsys.readouterr()
    assert main(["report", str(dataset_report.with_suffix(".json")), "--out", str(out)]) == 0
    assert f"report written to {out}" in capsys.readouterr().out
    plain = {r["parameter"] for r in ReportReader(out.read_text(encoding="utf-8")).rows(
        "effect-sizes")}
    assert not any(name.startswith("joint_compliance") for name in plain)


@pytest.mark.slow
def test_a_datasets_report_renders_in_headless_chromium(dataset_report: Path,
                                                        tmp_path: Path) -> None:
    assert "Is the model adequate?" in rendered_in_chromium(dataset_report, tmp_path)


def test_rewrites_a_runs_report(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    run = tmp_path / "run"
    (run / "sim").mkdir(parents=True)
    result = document()
    result["settings"] = {"effects": None, "plugins": [], "loss": "linear"}
    result["fit"]["effects"] = ["joint_offsets", "tool", "target", "joint_compliance"]
    (run / "result.json").write_text(json.dumps(result))
    save_dataset(hidden_dataset({"joint_compliance.c2": 2e-5}, seed=1, n_samples=40).dataset,
                 run / "dataset.json")
    (run / "sim" / "truth.json").write_text(json.dumps(
        {"zero_errors": [0.0] * 6, "effects": {"joint_compliance": [0, 2e-5, 0, 0, 0, 0]}}))
    assert main(["report", str(run)]) == 0
    assert "report written to" in capsys.readouterr().out
    report = ReportReader((run / "report.html").read_text(encoding="utf-8"))
    assert report.texts["verdict"].startswith("PASS")
    assert len(report.rows("offsets")) == 6 and "model-verdict" in report.texts
    sizes = {r["parameter"]: r for r in report.rows("effect-sizes")}
    assert sizes["joint_compliance.c2"]["true (simulation)"] != "not simulated by name"
    out = tmp_path / "only-result.html"
    assert main(["report", str(run), "--no-diagnosis", "--out", str(out)]) == 0
    assert "model-verdict" not in ReportReader(out.read_text(encoding="utf-8")).texts


def test_bad_input_exit_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["report", str(tmp_path / "nowhere")]) == 2
    assert "not a run folder nor a dataset file" in capsys.readouterr().err
    (tmp_path / "run").mkdir()
    assert main(["report", str(tmp_path / "run"), "--effects", "+geometry"]) == 2
    assert f"hostpc report {tmp_path / 'run' / 'dataset.json'} --effects" in \
        capsys.readouterr().err
    assert main(["report", str(tmp_path)]) == 2
    assert "no result document" in capsys.readouterr().err
    (tmp_path / "result.json").write_text("{broken")
    assert main(["report", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "cannot read the result document" in err and "Traceback" not in err
