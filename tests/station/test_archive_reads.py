"""Reading the archive never creates one: `hostpc history` and `fit --db` on a missing SQLite
file, or on a database without zerocal tables (SQLite and a real PostgreSQL server), are one
line and exit 2, and leave nothing behind; writers (the station, `calibrate --db`, through
`open_archive`'s default) still create a new archive."""

from __future__ import annotations

import os
import sqlite3
import subprocess
from pathlib import Path

import sqlalchemy as sa

from hostpc.archive import open_archive
from tests.station.conftest import REPO, hostpc_command


def _hostpc(cwd: Path, *args: str) -> subprocess.CompletedProcess[str]:
    """`hostpc ARGS` run from ``cwd`` (this checkout's package, whatever the folder)."""
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    return subprocess.run(hostpc_command(*args), cwd=cwd, env=env, capture_output=True,
                          text=True, timeout=120)


def _tables(url: str) -> list[str]:
    engine = sa.create_engine(url.replace("postgresql://", "postgresql+psycopg://"))
    try:
        with engine.connect() as connection:
            return sorted(sa.inspect(connection).get_table_names())
    finally:
        engine.dispose()


def test_history_and_fit_on_a_missing_sqlite_file_are_exit_2_and_create_nothing(
        tmp_path: Path) -> None:
    for args in (("history", "--db", "sqlite:///missing.db"),
                 ("fit", "--db", "sqlite:///missing.db", "--run", "1")):
        run = _hostpc(tmp_path, *args)
        assert run.returncode == 2, run.stderr
        assert run.stderr.count("\n") == 1 and "Traceback" not in run.stderr, run.stderr
        assert f"no archive at {tmp_path / 'missing.db'}" in run.stderr
        assert run.stderr.rstrip().endswith(f"ls {tmp_path}")
        assert "no archived runs" not in run.stdout
        assert list(tmp_path.iterdir()) == []  # no database, no -wal / -shm beside it


def test_a_database_without_zerocal_tables_is_exit_2_and_stays_empty(
        archive_url: str, tmp_path: Path) -> None:
    if archive_url.startswith("sqlite:"):  # an unrelated SQLite file at the path
        with sqlite3.connect(archive_url.removeprefix("sqlite:///")) as connection:
            connection.execute("CREATE TABLE unrelated (a INTEGER)")
        before = ["unrelated"]
    else:  # the fixture's fresh PostgreSQL database has no tables at all
        before = []
    assert _tables(archive_url) == before
    run = _hostpc(tmp_path, "history", "--db", archive_url)
    assert run.returncode == 2, run.stderr
    assert run.stderr.count("\n") == 1 and "no zerocal archive there" in run.stderr
    assert _tables(archive_url) == before  # no schema created by the read


def test_writers_still_create_the_archive_and_then_history_reads_it(
        archive_url: str, tmp_path: Path) -> None:
    with open_archive(archive_url) as archive:  # what the station and calibrate --db call
        assert archive.runs() == []
    assert {"zerocal_schema", "runs", "run_offsets"} <= set(_tables(archive_url))
    run = _hostpc(tmp_path, "history", "--db", archive_url)
    assert run.returncode == 0, run.stderr
    assert "no archived runs" in run.stdout
