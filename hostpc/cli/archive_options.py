"""`--db URL` for commands that archive a run or read one back (calibrate, fit, rollback);
a resume or rollback given none uses the archive its run names (`run_archive`)."""

from __future__ import annotations

import argparse
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

from hostpc.db_url import redacted_url

if TYPE_CHECKING:
    from hostpc.archive import RunRecord


def add_archive_options(parser: argparse.ArgumentParser, *, read: bool) -> None:
    parser.add_argument("--db", metavar="URL",
                        help="results archive: sqlite:///PATH or postgresql://USER@HOST/DB")
    if read:
        parser.add_argument("--run", type=int, metavar="ID",
                            help="with --db: refit the dataset of this archived run")
    else:
        parser.add_argument("--robot-serial", metavar="SERIAL",
                            help="the robot's serial number: the archive's key with --db (default: "
                            "its address), and the robot a cell reference belongs to")


def run_archive(args: argparse.Namespace, run_dir: Path) -> None:
    """A resume or rollback of the run in `run_dir` given no `--db`: the archive its
    run.json names (hostpc.calibrate.next_commands), so following a command printed
    without `--db` still revises the archived record."""
    from hostpc.calibrate.journal import Journal
    from hostpc.calibrate.run_header import read_run_header
    from hostpc.errors import InputError

    try:
        header = read_run_header(Journal(run_dir))
    except InputError:
        return  # the command itself says what is wrong with the run folder
    if not getattr(args, "db", None) and header.archive:
        args.db = header.archive
        print(f"archive: {header.archive} (the run's, from {run_dir}/run.json)",
              file=sys.stderr)


def archive_run(args: argparse.Namespace, run_dir: Path, exit_code: int,
                revise: Callable[[RunRecord], RunRecord] | None = None) -> None:
    """Archive the run in `run_dir` when `--db` was given; says so on stderr. A run
    without result.json only with `revise`, which states its record (a rollback of a run
    that stopped after its push: hostpc.cli.rollback)."""
    if not getattr(args, "db", None):
        return
    if revise is None and not (run_dir / "result.json").exists():
        return
    from hostpc.archive import open_archive, record_from_run

    recorded, address = _run_serial(run_dir)
    serial = args.robot_serial or recorded or str(args.robot or address or "unknown")
    with open_archive(args.db) as archive:
        record = record_from_run(run_dir, serial=serial, exit_code=exit_code)
        run_id = archive.add(record if revise is None else revise(record))
    print(f"archived as run {run_id} in {redacted_url(args.db)}", file=sys.stderr)


def _run_serial(run_dir: Path) -> tuple[str | None, str | None]:
    """The run's `--robot-serial` and its controller's address ("sim" for `--robot sim`)
    from run.json: a resume or rollback given neither archives it under the key it was
    started with."""
    from hostpc.calibrate.journal import Journal
    from hostpc.calibrate.run_header import read_run_header
    from hostpc.errors import InputError

    try:
        header = read_run_header(Journal(run_dir))
    except InputError:
        return None, None
    return header.robot_serial, "sim" if header.robot.sim else header.robot.address


def dataset_from_archive(args: argparse.Namespace) -> str:
    """The dataset of archived run `--run` written to a temporary file; returns its path."""
    from hostpc.archive import open_archive
    from hostpc.errors import InputError

    if args.run is None:
        raise InputError("--db needs --run ID (the archived run to refit)")
    with open_archive(args.db, create=False) as archive:
        stored = archive.run(args.run)
    if stored.dataset_json is None:
        raise InputError(f"--run {args.run}: the archived run has no dataset")
    path = _archived_folder() / f"run-{args.run}-dataset.json"
    path.write_text(stored.dataset_json)
    return str(path)


def _archived_folder() -> Path:
    """The one folder (this user's, mode 0700, in the temp dir) that holds the datasets
    read back from the archive, one file per archived run, rewritten on each read: the
    fit's next commands name the file, and repeated reads leave no new folders behind."""
    import os

    folder = Path(tempfile.gettempdir()) / f"zerocal-archived-{os.getuid()}"
    folder.mkdir(mode=0o700, exist_ok=True)
    info = folder.lstat()
    if folder.is_symlink() or not folder.is_dir() or info.st_uid != os.getuid():
        from hostpc.errors import InputError

        raise InputError(f"{folder}: not this user's folder; remove it, or set TMPDIR")
    return folder
