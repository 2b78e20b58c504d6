"""`hostpc fit --db URL --run ID` reads the archived dataset into one folder of this user,
rewritten on each read (review item 16: every read left a new /tmp/zerocal-archived-*
folder, 201 of them after a session), and `hostpc report` on a run that did not finish
says how to finish it."""

from __future__ import annotations

import tempfile
from pathlib import Path

import pytest

from hostpc.archive import open_archive, record_from_run
from hostpc.cli.main import main


def test_repeated_fits_from_the_archive_leave_one_folder(
        archive_url: str, sim_run_dir: Path, tmp_path: Path,
        monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    with open_archive(archive_url) as archive:
        run_id = archive.add(record_from_run(sim_run_dir, serial="R-9"))
    temp = tmp_path / "tmp"
    temp.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(temp))
    for _ in range(3):
        assert main(["fit", "--db", archive_url, "--run", str(run_id), "--cv-folds", "0"]) == 0
    capsys.readouterr()
    (folder,) = temp.iterdir()
    assert [p.name for p in folder.iterdir()] == [f"run-{run_id}-dataset.json"]
    assert folder.stat().st_mode & 0o077 == 0  # this user's only


def test_report_of_a_run_that_did_not_finish_names_the_resume(
        sim_run_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    run = tmp_path / "unfinished"
    run.mkdir()
    (run / "run.json").write_text((sim_run_dir / "run.json").read_text())
    assert main(["report", str(run)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert f"the run did not finish (ERROR); finish it with hostpc calibrate --resume {run}" \
        in err
