"""The rollback a FAIL prints keeps the run's archive (review item 4): `calibrate --db URL`
that FAILs verification printed `next: hostpc rollback --run RUN` without `--db`;
following it rolled the controller back but left the archive saying FAIL, and a later
`rollback --run RUN --db URL` was refused ("rolled back already"), so the archived record
could never be corrected. (A rollback given no --db now uses the run's archive too:
tests/integration/test_rollback_rules.py.) Against a real simulated controller (sockets)
and a real SQLite archive."""

from __future__ import annotations

import json
import shlex
from pathlib import Path

import pytest

from hostpc.archive import open_archive
from hostpc.cli.main import main
from hostpc.db_url import redacted_url
from hostpc.robots.simulator import SimulatedController
from tests.integration.calibrate_cli import robot_args
from tests.integration.test_calibrate_sim import sim_scenario, truth_rig_file


def test_the_printed_rollback_names_the_archive_and_revises_it(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    rig = truth_rig_file(sim_scenario(), tmp_path / "rig.json")
    run, url = tmp_path / "r1", f"sqlite:///{tmp_path / 'real.db'}"
    with SimulatedController(sim_scenario(), tmp_path / "stub") as sim:
        code = main(["calibrate", *robot_args(sim), "--known", "target", "--rig", str(rig),
                     "--poses", "8", "--verify-poses", "4", "--verify-tolerance", "0.001",
                     "--db", url, "--robot-serial", "SN-R1", "--out", str(run),
                     "--no-report"])
        assert code == 6
        outcome = json.loads((run / "result.json").read_text())["outcome"]
        assert outcome["verdict"] == "FAIL"
        command = f"hostpc rollback --run {run} --db {url}"
        assert outcome["next_command"] == command
        assert f"next: {command}" in capsys.readouterr().out
        assert json.loads((run / "run.json").read_text())["archive"] == url
        # a rollback without --db (as the old next line said): the run's archive, from
        # run.json, is revised all the same (it stayed FAIL before)
        assert main(["rollback", "--run", str(run), "--robot",
                     f"{sim.address.host}:{sim.address.port}"]) == 0
        with open_archive(url, create=False) as archive:
            (record,) = archive.runs("SN-R1")
            assert record.verdict == "ROLLED_BACK"
        # the printed command again: the run is rolled back already, so it (re)states the
        # archived record (nothing is rolled back twice) instead of refusing
        assert main(shlex.split(command)[1:]) == 0
        assert "rolled back already; its archived record now says ROLLED_BACK" in \
            capsys.readouterr().out
    with open_archive(url, create=False) as archive:
        (record,) = archive.runs("SN-R1")
        assert record.verdict == "ROLLED_BACK" and record.serial == "SN-R1"
        assert [r.verdict for r in archive.revisions(record.id)] == ["FAIL", "ROLLED_BACK"]


def test_an_archive_password_is_never_printed_nor_kept() -> None:
    """The run folder and the next command keep the archive's URL without its password
    (it comes from PGPASSWORD or ~/.pgpass, docs/station.md)."""
    assert redacted_url("postgresql://zc:s3cret@db.local:5433/cal") == \
        "postgresql://zc@db.local:5433/cal"
    assert redacted_url("postgresql://zc@db.local/cal") == "postgresql://zc@db.local/cal"
    assert redacted_url("sqlite:///runs/real.db") == "sqlite:///runs/real.db"


def test_the_archive_never_prints_a_password_in_its_errors() -> None:
    """The archive's own error lines name the URL without its password: a station's log
    and a terminal get them (they printed `--db URL` as given before)."""
    from hostpc.errors import ZerocalError

    for url in ("postgresql://zc:s3cret@127.0.0.1:1/cal",  # nothing listens on port 1
                "mysql://zc:s3cret@127.0.0.1/cal"):         # not an archive URL
        with pytest.raises(ZerocalError) as caught:
            with open_archive(url, create=False):
                pass
        assert "s3cret" not in str(caught.value), caught.value
        assert "zc@127.0.0.1" in str(caught.value)
