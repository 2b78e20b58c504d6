"""`--db URL` for commands that archive a run or read one back (calibrate, fit)."""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

from hostpc.db_url import redacted_url


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


def archive_run(args: argparse.Namespace, run_dir: Path, exit_code: int) -> None:
    """Archive the run in `run_dir` when `--db` was given; says so on stderr."""
    if not getattr(args, "db", None) or not (run_dir / "result.json").exists():
        return
    from hostpc.archive import open_archive, record_from_run

    serial = args.robot_serial or str(args.robot or "unknown")
    with open_archive(args.db) as archive:
        run_id = archive.add(record_from_run(run_dir, serial=serial, exit_code=exit_code))
    print(f"archived as run {run_id} in {redacted_url(args.db)}", file=sys.stderr)


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
