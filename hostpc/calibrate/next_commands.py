"""The next commands a run prints that act on the run again: its resume and its rollback.

One rule, one home: a run archived with `--db` (run.json `archive`, its URL without a
password, hostpc.db_url.redacted_url) names the archive in every such command, so that
following the command revises the archived record too (a resume's PASS, a rollback's
ROLLED_BACK). The commands fall back to run.json's archive when given no `--db`
(hostpc.cli.archive_options.run_archive), so a command printed without it (an older run's,
a hand-typed one) still reaches the archive. The password comes from PGPASSWORD or
~/.pgpass (hostpc.archive.database).
"""

from __future__ import annotations

from pathlib import Path

RESUME = "hostpc calibrate --resume"
ROLLBACK = "hostpc rollback --run"
_ARCHIVED_COMMANDS = (RESUME, ROLLBACK)


def with_archive(command: str, archive: str | None) -> str:
    """`command` with `--db ARCHIVE` if it resumes or rolls back a run (one command, not
    a choice of two) and the run is archived; else as it is."""
    if (archive and command.startswith(_ARCHIVED_COMMANDS) and " or " not in command
            and " --db " not in command):
        return f"{command} --db {archive}"
    return command


def resume_command(run_dir: str | Path, *options: str, archive: str | None = None) -> str:
    """`hostpc calibrate --resume RUN [OPTIONS] [--db ARCHIVE]`."""
    return with_archive(" ".join((RESUME, str(run_dir), *options)), archive)


def rollback_command(run_dir: str | Path, archive: str | None = None) -> str:
    """`hostpc rollback --run RUN [--db ARCHIVE]`."""
    return with_archive(f"{ROLLBACK} {run_dir}", archive)
