"""The station's and the archive's files are the JSON form of typed values: current.json
read back and written again gives the same bytes; the archive stores a run's result.json and
dataset.json as the documents the run wrote (the same JSON text), and reads them back as the
run's values."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import sqlalchemy as sa

from hostpc.archive import open_archive, record_from_run
from hostpc.archive.database import runs_table
from hostpc.archive.records import read_result
from hostpc.errors import InputError
from hostpc.files import write_json_atomic
from hostpc.station.status import CurrentRun


def test_current_json_reads_back_and_writes_the_same_bytes(tmp_path: Path) -> None:
    written = tmp_path / "current.json"  # as the station before typed values wrote it
    write_json_atomic(written, {"run_uid": "9b7c", "serial": "SN-1", "model": "ur5e",
                                "run_dir": "/runs/SN-1-20260101T000000000000",
                                "started_at": "2026-01-01T00:00:00+00:00", "attempts": 1})
    again = tmp_path / "again.json"
    current = CurrentRun.from_json(json.loads(written.read_text()))
    write_json_atomic(again, current.to_json())
    assert again.read_bytes() == written.read_bytes()
    assert (current.serial, current.attempts) == ("SN-1", 1)


@pytest.mark.parametrize("damaged", [{}, {"serial": "SN-1"}, {"run_uid": "u", "serial": "S",
                                                              "run_dir": "d"}])
def test_a_damaged_current_json_is_refused(damaged: dict[str, str]) -> None:
    with pytest.raises(KeyError):
        CurrentRun.from_json(damaged)


def test_the_archive_stores_the_run_documents_as_written(tmp_path: Path,
                                                         sim_run_dir: Path) -> None:
    url = f"sqlite:///{tmp_path / 'archive.db'}"
    with open_archive(url) as archive:
        run_id = archive.add(record_from_run(sim_run_dir, serial="SN-1"))
        with archive.engine.connect() as connection:
            row = connection.execute(sa.select(runs_table.c.result_json,
                                               runs_table.c.dataset_json)).one()
        stored = archive.run(run_id)
    result = json.loads((sim_run_dir / "result.json").read_text())
    dataset = json.loads((sim_run_dir / "dataset.json").read_text())
    assert row.result_json == json.dumps(result, allow_nan=True)
    assert row.dataset_json == json.dumps(dataset)
    assert stored.result == read_result(sim_run_dir / "result.json")
    assert stored.dataset_json == row.dataset_json
    assert stored.run.offsets and all(o.label for o in stored.run.offsets)


def test_a_result_that_is_no_calibration_result_is_one_input_error(tmp_path: Path) -> None:
    (tmp_path / "result.json").write_text(json.dumps({"format": "zerocal-calibration/1"}))
    with pytest.raises(InputError, match="not a calibration result document"):
        record_from_run(tmp_path, serial="SN-1")
