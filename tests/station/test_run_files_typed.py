"""result.json and run.json are the JSON form of frozen values (RunResult, RunHeader):
reading a run's files and writing them again gives the same keys, in the same order, with
the same values; a result written by an older version (blocks it did not have) too."""

from __future__ import annotations

import json
from pathlib import Path

from hostpc.calibrate.run_header import RunHeader
from hostpc.calibrate.run_result import RunResult


def test_result_json_reads_back_and_writes_the_same_document(sim_run_dir: Path) -> None:
    document = json.loads((sim_run_dir / "result.json").read_text(encoding="utf-8"))
    again = RunResult.from_dict(document).to_dict()
    assert json.dumps(again) == json.dumps(document)  # keys, their order and values


def test_run_json_reads_back_and_writes_the_same_header(sim_run_dir: Path) -> None:
    header = json.loads((sim_run_dir / "run.json").read_text(encoding="utf-8"))
    header.pop("format")  # Journal.write_header adds it
    assert json.dumps(RunHeader.from_dict(header).to_dict()) == json.dumps(header)


def test_an_older_result_keeps_its_shape(sim_run_dir: Path) -> None:
    document = json.loads((sim_run_dir / "result.json").read_text(encoding="utf-8"))
    for key in ("outcome", "reference_check", "method_setup", "robot_time_s", "verify"):
        document.pop(key, None)
    document["acquisition"].pop("n_poses_measured")
    run = RunResult.from_dict(document)
    assert run.outcome is None and run.acquisition.n_poses_measured is None
    assert json.dumps(run.to_dict()) == json.dumps(document)
