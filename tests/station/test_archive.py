"""The results archive against SQLite and a real PostgreSQL server: store, read back,
refit from the archive, migrate, and 4 processes writing concurrently."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
import sqlalchemy as sa

from hostpc.archive import open_archive, record_from_run
from hostpc.archive.database import SCHEMA_VERSION, ArchiveError
from tests.station.conftest import REPO, hostpc_command


def test_a_run_is_stored_whole_and_read_back(archive_url: str, sim_run_dir: Path) -> None:
    record = record_from_run(sim_run_dir, serial="R-1", model="ur5e", station="cell-1")
    result = json.loads((sim_run_dir / "result.json").read_text())
    with open_archive(archive_url) as archive:
        run_id = archive.add(record)
        assert archive.add(record) == run_id  # the same run is not stored twice
        runs = archive.runs()
        assert [r.id for r in runs] == [run_id]
        stored = archive.run(run_id)
    entry = stored.run
    assert entry.serial == "R-1" and entry.station == "cell-1"
    assert entry.verdict == record.verdict == "PASS"
    assert stored.result is not None and stored.result.to_dict() == result
    assert stored.dataset_json is not None
    assert json.loads(stored.dataset_json) == json.loads(
        (sim_run_dir / "dataset.json").read_text())
    pushed = [j for j in result["offsets"]["joints"] if j["pushed"]]
    offsets = {o.label: o for o in runs[0].offsets}
    for joint in pushed:
        assert offsets[joint["label"]].new_deg == pytest.approx(joint["new_deg"], abs=1e-12)
        assert offsets[joint["label"]].sigma_deg == pytest.approx(joint["sigma_deg"])
    assert runs[0].largest_correction_deg == pytest.approx(
        max(abs(j["correction_deg"]) for j in pushed))


def test_an_archived_run_refits_from_the_archive(archive_url: str, sim_run_dir: Path) -> None:
    with open_archive(archive_url) as archive:
        run_id = archive.add(record_from_run(sim_run_dir, serial="R-2"))
    from_archive = subprocess.run(hostpc_command("fit", "--db", archive_url, "--run", str(run_id),
                                                 "--json", "--cv-folds", "0"),
                                  cwd=REPO, capture_output=True, text=True, timeout=120)
    from_file = subprocess.run(hostpc_command("fit", str(sim_run_dir / "dataset.json"), "--json",
                                              "--cv-folds", "0"),
                               cwd=REPO, capture_output=True, text=True, timeout=120)
    assert from_archive.returncode == 0, from_archive.stderr
    archived, direct = json.loads(from_archive.stdout), json.loads(from_file.stdout)
    assert archived["parameters"] == direct["parameters"]
    missing = subprocess.run(hostpc_command("fit", "--db", archive_url, "--run", "999"),
                             cwd=REPO, capture_output=True, text=True, timeout=120)
    assert missing.returncode == 2
    assert missing.stderr.count("\n") == 1 and "no such run" in missing.stderr


def test_schema_is_versioned_and_a_newer_schema_is_refused(archive_url: str) -> None:
    with open_archive(archive_url) as archive:
        with archive.engine.begin() as connection:
            assert connection.exec_driver_sql("SELECT version FROM zerocal_schema").scalar() \
                == SCHEMA_VERSION
            connection.execute(sa.text("UPDATE zerocal_schema SET version = :v"),
                               {"v": SCHEMA_VERSION + 1})
    with pytest.raises(ArchiveError, match="newer than this zerocal"):
        open_archive(archive_url)


def test_an_old_schema_is_migrated(archive_url: str, sim_run_dir: Path) -> None:
    from hostpc.archive.database import MIGRATIONS, _engine, schema_table

    engine = _engine(archive_url)
    with engine.begin() as connection:  # a version-1 archive, as an older zerocal left it
        schema_table.create(connection)
        MIGRATIONS[0](connection)
        connection.execute(schema_table.insert().values(version=1))
    engine.dispose()
    with open_archive(archive_url) as archive:
        archive.add(record_from_run(sim_run_dir, serial="R-old"))
        with archive.engine.connect() as connection:
            assert connection.exec_driver_sql("SELECT version FROM zerocal_schema").scalar() \
                == SCHEMA_VERSION
        assert len(archive.runs("R-old")) == 1


def test_unreachable_archive_is_one_line_exit_3(tmp_path: Path) -> None:
    run = subprocess.run(hostpc_command("history", "--db", "postgresql://nobody@127.0.0.1:1/x"),
                         cwd=REPO, capture_output=True, text=True, timeout=120)
    assert run.returncode == 3 and run.stderr.count("\n") == 1, run.stderr
    bad = subprocess.run(hostpc_command("history", "--db", "mysql://x"), cwd=REPO,
                         capture_output=True, text=True, timeout=120)
    assert bad.returncode == 2 and "expected sqlite" in bad.stderr


WRITER = """
import sys, uuid
from datetime import UTC, datetime, timedelta
from hostpc.archive import open_archive, record_from_run
url, run_dir, worker, n_runs = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4])
start = datetime(2026, 1, 1, tzinfo=UTC)
with open_archive(url) as archive:
    for index in range(n_runs):
        archive.add(record_from_run(run_dir, serial=f"W{worker}-R{index:02d}",
                                    station=f"station-{worker}", run_uid=str(uuid.uuid4()),
                                    started_at=start + timedelta(minutes=index)))
"""


@pytest.mark.slow
def test_four_writers_concurrently_lose_and_duplicate_nothing(archive_url: str,
                                                              sim_run_dir: Path) -> None:
    """4 processes (as 4 stations would) archive 25 runs each into one database at once,
    each opening (and so migrating) the archive itself."""
    workers = [subprocess.Popen([sys.executable, "-c", WRITER, archive_url, str(sim_run_dir),
                                 str(w), "25"], cwd=REPO, stderr=subprocess.PIPE, text=True)
               for w in range(4)]
    for worker in workers:
        _, errors = worker.communicate(timeout=300)
        assert worker.returncode == 0, errors
    with open_archive(archive_url) as archive:
        runs = archive.runs()
    assert len(runs) == 100
    assert len({r.run_uid for r in runs}) == 100
    assert {r.serial for r in runs} == {f"W{w}-R{i:02d}" for w in range(4) for i in range(25)}
    assert all(len(r.offsets) == 6 for r in runs)
