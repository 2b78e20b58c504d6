"""The offsets a run folder's dataset was measured under (hostpc.calibrate.measured_under):
dataset.json's are run.json's initial offsets, verify_dataset.json's the last verification
round's; a dataset anywhere else, or a run whose files do not say, has none."""

from __future__ import annotations

from pathlib import Path

from hostpc.calibrate.journal import Journal
from hostpc.calibrate.journal_events import VerifyStart
from hostpc.calibrate.measured_under import MeasuredUnder, measured_under

INITIAL = [0.0, 0.01, -0.02, 0.0, 0.03, 0.0]
PUSHED = [0.0, 0.012, -0.021, 0.0, 0.031, 0.0]


def _run(folder: Path) -> Journal:
    journal = Journal(folder)
    journal.write_header({"settings": {"method": "stereo_target"},
                          "initial": {"robot": "ur5e", "zero_offsets": INITIAL}})
    for name in ("dataset.json", "verify_dataset.json", "copy.json"):
        (folder / name).write_text("{}")
    return journal


def test_a_run_folders_datasets_name_the_offsets_they_were_measured_under(
        tmp_path: Path) -> None:
    journal = _run(tmp_path / "r1")
    run = str((tmp_path / "r1").resolve())
    assert measured_under(tmp_path / "r1" / "dataset.json") == MeasuredUnder(
        run, "dataset.json", tuple(INITIAL))
    assert measured_under(tmp_path / "r1" / "verify_dataset.json") is None  # no round yet
    for number, offsets in ((1, INITIAL), (2, PUSHED)):  # the last round's
        journal.append(VerifyStart(round=number, first=4 * (number - 1),
                                   offsets=tuple(offsets), pushed_delta=(0.0,) * 6))
    assert measured_under(tmp_path / "r1" / "verify_dataset.json") == MeasuredUnder(
        run, "verify_dataset.json", tuple(PUSHED))
    assert measured_under(tmp_path / "r1" / "copy.json") is None  # another file of it


def test_a_dataset_outside_a_run_folder_or_a_broken_header_has_none(tmp_path: Path) -> None:
    (tmp_path / "dataset.json").write_text("{}")
    assert measured_under(tmp_path / "dataset.json") is None
    _run(tmp_path / "r2")
    (tmp_path / "r2" / "run.json").write_text('{"format": "zerocal-run/1"}')  # no initial
    assert measured_under(tmp_path / "r2" / "dataset.json") is None
