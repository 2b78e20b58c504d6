"""The results archive in a real database: SQLite (a file, the embedded default) or
PostgreSQL (one archive shared by many stations).

URLs: `sqlite:///PATH` (relative) or `sqlite:////ABS/PATH`, and
`postgresql://USER@HOST[:PORT]/DB` (driver psycopg 3; a password comes from the
environment, PGPASSWORD or ~/.pgpass, never from the command line).

Built on SQLAlchemy Core: one schema description serves both databases, it pools and
retries connections, and its dialects handle the SQL differences (autoincrement, JSON
text, timestamps), which hand-written SQL for two databases would repeat.

Schema versioning: table `zerocal_schema` holds the applied version; `MIGRATIONS[k]` takes
the schema from version k to k+1; `open_archive` applies the missing ones inside one
transaction under a lock (PostgreSQL advisory lock; SQLite's write lock), so stations that
start together migrate once.

Revisions (schema version 3): a run's outcome may change after it was archived (a
`--resume --force` pushes a refused run, `hostpc rollback --run` undoes a push). Archiving
the same run again (same run_uid, or the same run folder) then REVISES its record: the runs
row carries the current outcome and its `revision` number, and `run_revisions` keeps every
outcome the run had (revision, time, verdict, exit code, push status, the outcome block).

Reason and report (schema version 4): `reason` is the one-line reason of a run that did not
PASS (the station's; None where none was given), `report_path` the run's report.html.
"""

from __future__ import annotations

import json
import shlex
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import sqlalchemy as sa
from sqlalchemy.engine import Connection, Engine

from hostpc.archive.records import JointOffset, RunRecord
from hostpc.archive.rows import (
    ArchivedRun,
    Revision,
    StoredRun,
    archived_run,
    as_utc,
    stored_result,
)
from hostpc.db_url import redacted_url
from hostpc.errors import InputError, ZerocalError
from hostpc.kinematics.robots import canonical_name


class ArchiveError(ZerocalError):
    """The archive database cannot be reached or refused a write."""

    exit_code = 3


metadata = sa.MetaData()

schema_table = sa.Table("zerocal_schema", metadata,
                        sa.Column("version", sa.Integer, nullable=False))

runs_table = sa.Table(
    "runs", metadata,
    sa.Column("id", sa.Integer, primary_key=True, autoincrement=True),
    sa.Column("run_uid", sa.String(64), nullable=False, unique=True),
    sa.Column("serial", sa.String(64), nullable=False, index=True),
    sa.Column("model", sa.String(64), nullable=False),
    sa.Column("station", sa.String(64), nullable=False),
    sa.Column("started_at", sa.DateTime(timezone=True), nullable=False),
    sa.Column("archived_at", sa.DateTime(timezone=True), nullable=False),
    sa.Column("method", sa.String(32), nullable=False),
    sa.Column("effects", sa.Text, nullable=False),
    sa.Column("verdict", sa.String(16), nullable=False),
    sa.Column("exit_code", sa.Integer, nullable=False),
    sa.Column("push_status", sa.String(32), nullable=False),
    sa.Column("largest_correction_deg", sa.Float, nullable=True),
    sa.Column("software_version", sa.String(32), nullable=False),
    sa.Column("run_dir", sa.Text, nullable=False),
    sa.Column("result_json", sa.Text, nullable=False),
    sa.Column("dataset_json", sa.Text, nullable=True),
    sa.Column("revision", sa.Integer, nullable=False, server_default="1"),
    sa.Column("reason", sa.Text, nullable=True),
    sa.Column("report_path", sa.Text, nullable=True),
)

revisions_table = sa.Table(
    "run_revisions", metadata,
    sa.Column("run_id", sa.Integer, sa.ForeignKey("runs.id", ondelete="CASCADE"),
              nullable=False, index=True),
    sa.Column("revision", sa.Integer, nullable=False),
    sa.Column("revised_at", sa.DateTime(timezone=True), nullable=False),
    sa.Column("verdict", sa.String(16), nullable=False),
    sa.Column("exit_code", sa.Integer, nullable=False),
    sa.Column("push_status", sa.String(32), nullable=False),
    sa.Column("outcome_json", sa.Text, nullable=True),
)

offsets_table = sa.Table(
    "run_offsets", metadata,
    sa.Column("run_id", sa.Integer, sa.ForeignKey("runs.id", ondelete="CASCADE"),
              nullable=False, index=True),
    sa.Column("joint", sa.Integer, nullable=False),
    sa.Column("label", sa.String(32), nullable=False),
    sa.Column("old_deg", sa.Float, nullable=True),
    sa.Column("correction_deg", sa.Float, nullable=True),
    sa.Column("sigma_deg", sa.Float, nullable=True),
    sa.Column("new_deg", sa.Float, nullable=True),
    sa.Column("pushed", sa.Boolean, nullable=False),
)


def _migrate_0_to_1(connection: Connection) -> None:
    runs_table.create(connection)
    offsets_table.create(connection)


def _migrate_1_to_2(connection: Connection) -> None:
    # version 2: runs are looked up per robot in time order (history, drift)
    # (plain DDL: an sa.Index on runs_table would attach itself to the table description)
    connection.exec_driver_sql("CREATE INDEX ix_runs_serial_started ON runs (serial, started_at)")


def _migrate_2_to_3(connection: Connection) -> None:
    # version 3: a run's record is revised when its outcome changes; the history is kept
    columns = {c["name"] for c in sa.inspect(connection).get_columns("runs")}
    if "revision" not in columns:  # (a version-1 table created from today's description
        connection.exec_driver_sql(  # already has it)
            "ALTER TABLE runs ADD COLUMN revision INTEGER NOT NULL DEFAULT 1")
    revisions_table.create(connection, checkfirst=True)
    connection.exec_driver_sql(
        "INSERT INTO run_revisions (run_id, revision, revised_at, verdict, exit_code, "
        "push_status) SELECT id, 1, archived_at, verdict, exit_code, push_status FROM runs")


def _migrate_3_to_4(connection: Connection) -> None:
    # version 4: a run's one-line reason and the path of its report.html
    columns = {c["name"] for c in sa.inspect(connection).get_columns("runs")}
    for name in ("reason", "report_path"):
        if name not in columns:  # (a table created from today's description has them)
            connection.exec_driver_sql(f"ALTER TABLE runs ADD COLUMN {name} TEXT")


MIGRATIONS: tuple[Callable[[Connection], None], ...] = (_migrate_0_to_1, _migrate_1_to_2,
                                                        _migrate_2_to_3, _migrate_3_to_4)
SCHEMA_VERSION = len(MIGRATIONS)
_ADVISORY_LOCK_KEY = 4_711_042  # arbitrary, constant: "zerocal archive migration"


def _existing_sqlite(url: str) -> sa.engine.URL:
    """The SQLite URL of an archive file that must already exist, opened read-write without
    create (a URI filename with ``mode=rw``): a read never leaves an empty archive behind,
    e.g. when run from the wrong folder. InputError (exit 2) when the file is missing."""
    parsed = sa.engine.make_url(url)
    if not parsed.database or parsed.database == ":memory:" or "uri" in parsed.query:
        return parsed  # nothing on disk to create, or the caller's own URI
    path = Path(parsed.database).resolve()
    if not path.is_file():
        raise InputError(f"--db {redacted_url(url)}: no archive at {path} (reading never "
                         f"creates one; a calibration with --db or the station does): {_look(url)}")
    return parsed.set(database=path.as_uri()).update_query_dict({"mode": "rw", "uri": "true"})


def _look(url: str) -> str:
    """The command that shows what is at ``url`` (where the archive may be instead)."""
    if url.startswith("sqlite:"):
        folder = Path(sa.engine.make_url(url).database or ".").resolve().parent
        return f"ls {shlex.quote(str(folder))}"
    return f"psql {shlex.quote(redacted_url(url))} -c '\\dt'"


def _engine(url: str, create: bool = True) -> Engine:
    if url.startswith("sqlite:"):
        # several stations may write one file: wait for the lock instead of failing
        engine = sa.create_engine(url if create else _existing_sqlite(url),
                                  connect_args={"timeout": 60})

        @sa.event.listens_for(engine, "connect")
        def _pragmas(dbapi_connection: Any, _record: Any) -> None:
            dbapi_connection.isolation_level = None  # SQLAlchemy emits BEGIN itself
            cursor = dbapi_connection.cursor()
            cursor.execute("PRAGMA journal_mode=WAL")
            cursor.execute("PRAGMA foreign_keys=ON")
            cursor.close()

        @sa.event.listens_for(engine, "begin")
        def _begin(connection: Connection) -> None:
            # take the write lock at the start of each transaction: concurrent writers
            # (stations, the migration) queue instead of failing mid-transaction
            connection.exec_driver_sql("BEGIN IMMEDIATE")
        return engine
    if url.startswith(("postgresql://", "postgres://", "postgresql+psycopg://")):
        scheme, rest = url.split("://", 1)
        return sa.create_engine(f"postgresql+psycopg://{rest}", pool_pre_ping=True)
    raise InputError(f"--db {redacted_url(url)}: expected sqlite:///PATH or postgresql://USER@HOST/DB")


def _current_version(connection: Connection) -> int:
    if not sa.inspect(connection).has_table("zerocal_schema"):
        return 0
    version = connection.execute(sa.select(schema_table.c.version)).scalar()
    return int(version or 0)


def _migrate(engine: Engine, url: str, create: bool = True) -> None:
    with engine.begin() as connection:
        if engine.dialect.name == "postgresql":
            connection.execute(sa.text("SELECT pg_advisory_xact_lock(:key)"),
                               {"key": _ADVISORY_LOCK_KEY})
        if not create and not sa.inspect(connection).has_table("zerocal_schema"):
            raise InputError(f"--db {redacted_url(url)}: no zerocal archive there (no "
                             "zerocal tables; reading never creates them, a calibration with "
                             f"--db or the station does): {_look(url)}")
        schema_table.create(connection, checkfirst=True)
        version = _current_version(connection)
        if version > SCHEMA_VERSION:
            raise ArchiveError(f"archive schema version {version} is newer than this zerocal "
                               f"({SCHEMA_VERSION}): upgrade zerocal")
        for step in MIGRATIONS[version:]:
            step(connection)
        if version == 0 and not connection.execute(sa.select(schema_table)).first():
            connection.execute(schema_table.insert().values(version=SCHEMA_VERSION))
        elif version != SCHEMA_VERSION:
            connection.execute(schema_table.update().values(version=SCHEMA_VERSION))


def _store_offsets(connection: Connection, run_id: int,
                   offsets: tuple[JointOffset, ...]) -> None:
    if offsets:
        connection.execute(offsets_table.insert().values([
            {"run_id": run_id, "joint": o.joint, "label": o.label, "old_deg": o.old_deg,
             "correction_deg": o.correction_deg, "sigma_deg": o.sigma_deg,
             "new_deg": o.new_deg, "pushed": o.pushed} for o in offsets]))


def _outcome_json(record: RunRecord) -> str | None:
    outcome = record.result.outcome if record.result is not None else None
    return None if outcome is None else json.dumps(outcome, allow_nan=True)


def _result_json(record: RunRecord) -> str:
    """The run's result.json as the archive stores it ({} for a run that wrote none)."""
    return json.dumps(record.result.to_dict() if record.result is not None else {},
                      allow_nan=True)


class Archive:
    """An open archive. `add` stores a run (idempotent by run_uid; a changed outcome
    revises the record); `runs` lists runs (`ArchivedRun`) in time order; `run` returns one
    with its result and dataset; `revisions` the outcomes a run has had."""

    def __init__(self, engine: Engine, url: str):
        self.engine = engine
        self.url = redacted_url(url)  # shown in messages: never a password

    def add(self, record: RunRecord) -> int:
        """Store `record`; returns its archive id. A record whose run_uid (or run folder)
        is already stored is not stored twice: if its outcome (verdict, exit code, push
        status, result) changed, the stored record is revised (module docstring)."""
        archived_at, result_json = datetime.now(UTC), _result_json(record)
        values = {  # the runs row's columns (bind parameters, the database's boundary)
            "run_uid": record.run_uid, "serial": record.serial,
            "model": canonical_name(record.model),
            "station": record.station, "started_at": as_utc(record.started_at),
            "archived_at": archived_at, "method": record.method,
            "effects": json.dumps(list(record.effects)), "verdict": record.verdict,
            "exit_code": record.exit_code, "push_status": record.push_status,
            "largest_correction_deg": record.largest_correction_deg,
            "software_version": record.software_version, "run_dir": record.run_dir,
            "result_json": result_json, "dataset_json": record.dataset_json,
            "reason": record.reason or None, "report_path": record.report_path or None,
        }
        try:
            with self.engine.begin() as connection:
                existing = self._stored(connection, record)
                if existing is not None:
                    keep = ("run_uid", "serial", "model", "station", "started_at")
                    update = runs_table.update().values(
                        **{k: v for k, v in values.items() if k not in keep})
                    return self._revise(connection, existing, record, update, archived_at,
                                        result_json)
                key = connection.execute(runs_table.insert().values(**values)).inserted_primary_key
                assert key is not None  # an insert's result has its primary key
                run_id = int(key[0])
                _store_offsets(connection, run_id, record.offsets)
                connection.execute(revisions_table.insert().values(
                    run_id=run_id, revision=1, revised_at=archived_at,
                    verdict=record.verdict, exit_code=record.exit_code,
                    push_status=record.push_status, outcome_json=_outcome_json(record)))
                return run_id
        except sa.exc.IntegrityError:  # a concurrent writer stored the same uid first
            with self.engine.connect() as connection:
                existing = connection.execute(sa.select(runs_table.c.id).where(
                    runs_table.c.run_uid == record.run_uid)).scalar()
            if existing is None:
                raise
            return int(existing)
        except sa.exc.SQLAlchemyError as exc:
            raise ArchiveError(f"archive {self.url}: cannot store run "
                               f"({_first_line(exc)})") from None

    @staticmethod
    def _stored(connection: Connection, record: RunRecord) -> Any:
        """The stored row (id, revision, outcome columns) of the same run, or None: same
        run_uid, else, for a uid derived from the folder, the same run folder (a run
        resumed by hand after the station archived it under the station's uid)."""
        columns = (runs_table.c.id, runs_table.c.revision, runs_table.c.verdict,
                   runs_table.c.exit_code, runs_table.c.push_status, runs_table.c.result_json,
                   runs_table.c.reason, runs_table.c.report_path)
        row = connection.execute(sa.select(*columns).where(
            runs_table.c.run_uid == record.run_uid)).first()
        if row is None and record.uid_from_folder and record.run_dir:
            folders = {record.run_dir, str(Path(record.run_dir).resolve())}
            row = connection.execute(sa.select(*columns).where(
                runs_table.c.run_dir.in_(folders)).order_by(runs_table.c.id.desc())).first()
        return row

    @staticmethod
    def _revise(connection: Connection, row: Any, record: RunRecord, update: sa.Update,
                archived_at: datetime, result_json: str) -> int:
        """Revise the stored run `row` to `record`'s outcome (`update`: its new columns)
        if it changed; its id."""
        run_id = int(row.id)
        if (row.verdict, row.exit_code, row.push_status, row.result_json, row.reason,
                row.report_path) == (record.verdict, record.exit_code, record.push_status,
                                     result_json, record.reason or None,
                                     record.report_path or None):
            return run_id
        revision = int(row.revision or 1) + 1
        connection.execute(update.where(runs_table.c.id == run_id).values(revision=revision))
        connection.execute(offsets_table.delete().where(offsets_table.c.run_id == run_id))
        _store_offsets(connection, run_id, record.offsets)
        connection.execute(revisions_table.insert().values(
            run_id=run_id, revision=revision, revised_at=archived_at,
            verdict=record.verdict, exit_code=record.exit_code,
            push_status=record.push_status, outcome_json=_outcome_json(record)))
        return run_id

    def revisions(self, run_id: int) -> list[Revision]:
        """The outcomes run `run_id` has had, oldest first."""
        try:
            with self.engine.connect() as connection:
                rows = connection.execute(
                    sa.select(revisions_table).where(revisions_table.c.run_id == run_id)
                    .order_by(revisions_table.c.revision)).all()
        except sa.exc.SQLAlchemyError as exc:
            raise ArchiveError(f"archive {self.url}: cannot read ({_first_line(exc)})") from None
        return [Revision(run_id=int(row.run_id), revision=int(row.revision),
                         revised_at=as_utc(row.revised_at).isoformat(), verdict=row.verdict,
                         exit_code=int(row.exit_code), push_status=row.push_status,
                         outcome=None if row.outcome_json is None
                         else json.loads(row.outcome_json)) for row in rows]

    def runs(self, serial: str | None = None) -> list[ArchivedRun]:
        """Every run (of one robot if `serial`), oldest first, with its per-joint offsets
        (no dataset or result document: see `run`)."""
        query = sa.select(*[c for c in runs_table.c
                            if c.name not in ("result_json", "dataset_json")])
        if serial is not None:
            query = query.where(runs_table.c.serial == serial)
        query = query.order_by(runs_table.c.started_at, runs_table.c.id)
        try:
            with self.engine.connect() as connection:
                rows = connection.execute(query).all()
                offsets = self._offsets(connection, [int(row.id) for row in rows])
        except sa.exc.SQLAlchemyError as exc:
            raise ArchiveError(f"archive {self.url}: cannot read ({_first_line(exc)})") from None
        return [archived_run(row, offsets[int(row.id)]) for row in rows]

    @staticmethod
    def _offsets(connection: Connection, ids: list[int]
                 ) -> dict[int, tuple[JointOffset, ...]]:
        """Run id -> its per-joint offsets, by joint."""
        found: dict[int, list[JointOffset]] = {i: [] for i in ids}
        if ids:
            for o in connection.execute(sa.select(offsets_table).where(
                    offsets_table.c.run_id.in_(ids)).order_by(offsets_table.c.joint)):
                found[int(o.run_id)].append(JointOffset(
                    joint=o.joint, label=o.label, old_deg=o.old_deg,
                    correction_deg=o.correction_deg, sigma_deg=o.sigma_deg,
                    new_deg=o.new_deg, pushed=o.pushed))
        return {i: tuple(rows) for i, rows in found.items()}

    def run(self, run_id: int) -> StoredRun:
        """One run with its result and its dataset document."""
        try:
            with self.engine.connect() as connection:
                row = connection.execute(sa.select(runs_table).where(
                    runs_table.c.id == run_id)).first()
                offsets = self._offsets(connection, [run_id])[run_id]
        except sa.exc.SQLAlchemyError as exc:
            raise ArchiveError(f"archive {self.url}: cannot read ({_first_line(exc)})") from None
        if row is None:
            raise InputError(f"--run {run_id}: no such run in the archive {self.url}")
        return StoredRun(archived_run(row, offsets), stored_result(row.result_json),
                         row.dataset_json)

    def report_path(self, run_id: int) -> str | None:
        """The report.html path archived with run `run_id` (None: no such run or none)."""
        try:
            with self.engine.connect() as connection:
                path = connection.execute(sa.select(runs_table.c.report_path).where(
                    runs_table.c.id == run_id)).scalar()
        except sa.exc.SQLAlchemyError as exc:
            raise ArchiveError(f"archive {self.url}: cannot read ({_first_line(exc)})") from None
        return None if path is None else str(path)

    def close(self) -> None:
        self.engine.dispose()

    def __enter__(self) -> Archive:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _first_line(exc: BaseException) -> str:
    text = str(getattr(exc, "orig", None) or exc)
    return text.strip().splitlines()[0] if text.strip() else type(exc).__name__


def open_archive(url: str, *, create: bool = True) -> Archive:
    """Connect to the archive at `url`, migrating its schema. Writers (the station,
    `calibrate --db`) create a missing archive; readers pass ``create=False``: a missing
    SQLite file or a database without zerocal tables is then an InputError (exit 2) and
    nothing is created."""
    engine = _engine(url, create)
    try:
        _migrate(engine, url, create)
    except sa.exc.SQLAlchemyError as exc:
        engine.dispose()
        raise ArchiveError(f"archive {redacted_url(url)}: cannot open "
                           f"({_first_line(exc)})") from None
    except InputError:
        engine.dispose()
        raise
    return Archive(engine, url)


@contextmanager
def archive_at(url: str) -> Iterator[Archive]:
    archive = open_archive(url)
    try:
        yield archive
    finally:
        archive.close()
