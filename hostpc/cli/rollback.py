"""`hostpc rollback`: restore the zero offsets a calibration push replaced.

    hostpc rollback --run DIR [--robot HOST[:PORT]]      the push recorded in DIR/push.json
    hostpc rollback --robot HOST[:PORT] --id ROLLBACK_ID the controller's rollback id

With --run, the controller address defaults to the one the run pushed to, push.json is
validated first (hostpc.calibrate.push_file: one line, exit 2, nothing written, for a file
that is not this run's push or not this controller's joint count), and if the controller
no longer knows the rollback id (it restarted), or its rollback leaves other offsets than
the ones read before the push, the previous offsets saved in push.json are written
directly. A push.json without a rollback id (the run stopped between
recording its intent and the controller's answer) is settled from the controller's offsets:
the intended new ones -> the previous ones are written; still the previous ones -> nothing
to undo. A run whose journal shows that no push reached the controller (refused, e.g. by
the controller's own offset limit) is answered from the journal; a run against `--robot
sim` has no controller left (its simulator ended with the run): both without connecting.
Offsets are printed in degrees.

With --run, the rollback is journaled and the run's outcome is derived again: result.json
(outcome verdict ROLLED_BACK, no joint calibrated), summary.txt and report.html say so; the
archived record of the run is revised (hostpc.archive: its history of outcomes is kept):
in the archive --db names, else the one the run's run.json names; a run that stopped
after its push (no result.json) from its journal. With --run, a controller that holds
neither the offsets the run pushed nor the ones it replaced (a later push, e.g. the next
robot's on a station) is refused, exit 2, nothing written, unless --discard-later-push.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import math
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from hostpc.calibrate.journal import Journal
from hostpc.calibrate.journal_events import Pushed, PushRecord, Rollback
from hostpc.calibrate.next_commands import resume_command, rollback_command
from hostpc.calibrate.outcome import EXIT_CODES
from hostpc.calibrate.outcome_files import rewrite_outcome
from hostpc.calibrate.push import rollback, rollback_run, same_offsets
from hostpc.calibrate.push_file import PushFile, check_joint_count, read_push_file
from hostpc.calibrate.run_header import read_run_header
from hostpc.cli.archive_options import add_archive_options, archive_run, run_archive
from hostpc.cli.numbers import TIMEOUT_S
from hostpc.db_url import redacted_url
from hostpc.errors import (
    ConnectionFailed,
    ControllerError,
    InputError,
    ProtocolViolation,
    RequestTimeout,
)
from hostpc.robots.connect import RobotAddress, open_robot, parse_robot
from hostpc.robots.drivers import DEFAULT_DRIVER, DRIVER_NAMES, DRIVERS

if TYPE_CHECKING:
    from hostpc.archive import RunRecord


DISCARD_LATER = "--discard-later-push"
"""The override of the refusal to roll back over a later push (`_refuse_later_push`)."""


def register(subparsers: Any) -> None:
    """Add the `rollback` subcommand."""
    parser = subparsers.add_parser(
        "rollback",
        help="restore the zero offsets replaced by a calibration push",
        description="Undo a `hostpc calibrate` push: by run folder (push.json) or rollback id.",
    )
    parser.add_argument("--robot", metavar="HOST[:PORT]",
                        help="controller address (default: the one recorded in the run)")
    parser.add_argument("--driver", choices=DRIVER_NAMES, default=DEFAULT_DRIVER)
    parser.add_argument("--run", metavar="DIR", help="calibration run folder")
    parser.add_argument("--id", dest="rollback_id", help="the controller's rollback id")
    parser.add_argument("--token", help="shared token (default: $ZEROCAL_TOKEN, else the "
                        "simulator's default)")
    parser.add_argument("--timeout", type=TIMEOUT_S, default=10.0, help="seconds per request")
    parser.add_argument("--json", action="store_true", help="print JSON")
    parser.add_argument(DISCARD_LATER, action="store_true",
                        help="with --run: roll back although the controller holds other "
                        "offsets than this run pushed (a later push, e.g. the next robot's "
                        "on a station): they are overwritten")
    add_archive_options(parser, read=False)
    parser.epilog = ("with --run and no --db: the archive the run's run.json names is "
                     "revised (docs/calibrate.md)")
    parser.set_defaults(func=run)


def _run_driver(run_dir: Path) -> str | None:
    """The driver recorded in a run folder's run.json (None if unreadable)."""
    try:
        return read_run_header(Journal(run_dir)).robot.driver
    except InputError:
        return None


def run(args: argparse.Namespace) -> int:
    """Entry point of `hostpc rollback`; returns the exit code."""
    if bool(args.run) == bool(args.rollback_id):
        raise InputError("give exactly one of --run DIR and --id ROLLBACK_ID")
    for name in (args.driver, _run_driver(Path(args.run)) if args.run else None):
        driver = DRIVERS.get(name or "")
        if driver is not None and driver.no_rollback:  # e.g. a UR: offsets on the host
            raise InputError(driver.no_rollback)
    previous: np.ndarray | None = None
    push: PushFile | None = None
    address: RobotAddress | None = parse_robot(args.robot) if args.robot else None
    if args.run:
        run_archive(args, Path(args.run))  # no --db: the run's own (next_commands.py)
        if args.db and _archive_rolled_back(Path(args.run), args):
            return 0
        _refuse_if_rolled_back(Path(args.run))
        nothing = _nothing_pushed(Path(args.run))
        if nothing is not None:  # known from the journal: no controller to ask
            print(nothing)
            return 0
        if address is None and _ran_simulated(Path(args.run)):
            raise InputError(f"--run {args.run}: it ran against `--robot sim`, whose "
                             "simulated controller lived only as long as the run: there is "
                             "nothing left to roll back")
        push = read_push_file(Path(args.run))
        rollback_id = push.record.rollback_id or "(none: push recorded as intent)"
        previous = push.record.previous
        if address is None and push.controller:
            address = parse_robot(push.controller)
    else:
        rollback_id = str(args.rollback_id)
    if address is None:
        raise InputError("--robot HOST[:PORT] is required")
    if address.sim:
        raise InputError("--robot sim: a simulated controller lives only as long as its run; "
                         "give the address of a running controller")
    try:
        now, how = asyncio.run(_rollback(address, args, rollback_id, previous, push))
    except (ConnectionFailed, RequestTimeout, ProtocolViolation) as exc:
        again = f"--run {args.run}" if args.run else f"--robot {address} --id {rollback_id}"
        raise type(exc)(f"{exc}; the rollback was cut short: see what the controller holds "
                        f"with: hostpc status --robot {address}; then roll back again with: "
                        f"hostpc rollback {again}") from exc
    matches = previous is None or same_offsets(now, previous)
    outcome = None
    if args.run and how != "not_pushed":
        _journal_rollback(Path(args.run), now, how, str(address))
        outcome = rewrite_outcome(Path(args.run))  # result.json, summary, report say so
        if outcome is not None:
            archive_run(args, Path(args.run), outcome.exit_code)
        elif push is not None:  # stopped after its push (ERROR): from the journal
            _archive_from_journal(args, Path(args.run), push.record)
    document = {
        "controller": str(address),
        "rollback_id": push.record.rollback_id if push is not None else rollback_id,
        "method": how,
        "offsets_deg": [math.degrees(v) for v in now],
        "previous_offsets_deg": None if previous is None else [math.degrees(v)
                                                               for v in previous],
        "restored": matches,
        "outcome": None if outcome is None else outcome.to_dict(),
    }
    if args.json:
        print(json.dumps(document, indent=2))
    else:
        if how == "not_pushed":
            print(f"nothing to roll back on {address}: the push recorded in {args.run} never "
                  "reached the controller (it has the previous offsets)")
        else:
            note = {"rollback_id": "",
                    "previous_offsets_written": " (wrote the saved previous offsets)"}[how]
            print(f"rolled back {rollback_id} on {address}{note}")
        print("zero offsets now [deg]: " + ", ".join(
            f"J{j + 1} {math.degrees(v):+.5f}" for j, v in enumerate(now)))
        if outcome is not None:
            print(f"{args.run}: {outcome.headline} (result.json, summary.txt rewritten)")
    if not matches:
        print(f"hostpc rollback: after the rollback the controller at {address} still does "
              "not hold the offsets read before the push (it holds the ones above); see what "
              f"it holds with: hostpc status --robot {address}", file=sys.stderr)
    return 0 if matches else ControllerError.exit_code


async def _rollback(address: RobotAddress, args: argparse.Namespace, rollback_id: str,
                    previous: np.ndarray | None, push: PushFile | None
                    ) -> tuple[np.ndarray, str]:
    """(offsets now (n,) rad, how): by the run's push record if given, else by id."""
    robot = await open_robot(address, args.driver, token=args.token, timeout=args.timeout)
    try:
        if push is not None:
            now = np.asarray(await robot.get_offsets(), float)
            check_joint_count(push, now.size, args.run, str(address))
            if push.status != "intent" and not args.discard_later_push:
                # an intent's read-back never came: what it holds is unknown
                _refuse_later_push(now, push, Path(args.run), address,
                                   redacted_url(args.db) if args.db else None)
            return await rollback_run(robot, push.record, now)
        return await rollback(robot, rollback_id, previous)
    finally:
        await robot.close()


def _refuse_if_rolled_back(run_dir: Path) -> None:
    """InputError if the run's latest push was rolled back already: the controller may hold
    a later run's verified offsets by now, and a second rollback would silently discard
    them (review R1)."""
    journal = Journal(run_dir)
    if not journal.exists:
        return
    last = journal.last_event(Pushed, Rollback)  # reads the journal on first use
    if isinstance(last, Rollback):
        raise InputError(f"--run {run_dir}: its push was rolled back already "
                         f"({last.time or 'at an unrecorded time'}); nothing of it is "
                         f"left to undo ({status_hint(run_dir)})")


def _archive_rolled_back(run_dir: Path, args: argparse.Namespace) -> bool:
    """A run rolled back already, given `--db`: revise its archived record to the rolled
    back outcome (a rollback whose archive was not reached left it saying PASS/FAIL/ERROR);
    True if done. Nothing is rolled back twice."""
    journal = Journal(run_dir)
    if not journal.exists or not isinstance(journal.last_event(Pushed, Rollback), Rollback):
        return False
    if (run_dir / "result.json").is_file():
        result = json.loads((run_dir / "result.json").read_text(encoding="utf-8"))
        archive_run(args, run_dir, int(result["exit_code"]))
        verdict = (result.get("outcome") or {}).get("verdict", "ROLLED_BACK")
    else:  # stopped after its push (ERROR): from the journal, as the rollback did
        _archive_from_journal(args, run_dir, read_push_file(run_dir).record)
        verdict = "ROLLED_BACK"
    print(f"{run_dir}: rolled back already; its archived record now says {verdict}")
    return True


def status_hint(run_dir: Path) -> str:
    """How to see what the run's controller holds now, with its address."""
    try:
        header = read_run_header(Journal(run_dir))
    except InputError:
        return "to see what the controller holds now: hostpc status --robot HOST"
    robot = header.robot
    if robot.sim:
        return ("a --robot sim run: its simulated controller starts from the run's initial "
                "offsets again; to push again: "
                + resume_command(run_dir, "--push", archive=header.archive))
    return f"to see what the controller holds now: hostpc status --robot {robot.address}"


def _ran_simulated(run_dir: Path) -> bool:
    """True if the run's run.json says it ran against `--robot sim`."""
    try:
        return read_run_header(Journal(run_dir)).robot.sim
    except InputError:
        return False


def _nothing_pushed(run_dir: Path) -> str | None:
    """The line saying the run's journal shows no push that reached the controller (a
    push the controller refused leaves its intent in push.json), or None: then push.json
    and the controller decide."""
    journal = Journal(run_dir)
    if not journal.exists or journal.events("push"):
        return None
    last = journal.last_event("push_intent", "push_refused")
    if last is not None and last.get("event") == "push_intent":
        return None  # cut short: only the controller's offsets tell
    if last is None and not (run_dir / "push.json").is_file():
        return None  # read_push_file says so
    return (f"nothing to roll back: {run_dir} wrote no offsets to the controller (its push "
            "was refused); the controller's offsets are the ones the run found")


def _journal_rollback(run_dir: Path, now: np.ndarray, how: str, controller: str) -> None:
    """Record the rollback in the run's journal, so that `hostpc calibrate --resume` says
    "rolled back" (and only then: previous offsets without this event mean a lost push)."""
    import datetime as _dt


    journal = Journal(run_dir)
    if journal.exists:
        journal.append(Rollback(how=how, controller=controller,
                                offsets=tuple(float(v) for v in now),
                                time=_dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")))


def _refuse_later_push(now: np.ndarray, push: PushFile, run_dir: Path,
                       address: RobotAddress, archive: str | None) -> None:
    """InputError (nothing written) if the controller's offsets are neither the ones this
    run pushed (or held after the push, `PushRecord.held`) nor the ones it replaced:
    someone pushed later (on a station: the next robot's run), and rolling back would
    overwrite that push with this run's previous offsets."""
    record = push.record
    if record.rollback_id is None:
        return  # settled from the offsets by rollback_run, which refuses this case
    if any(same_offsets(now, offsets) for offsets in (record.new, record.previous,
                                                      record.held) if offsets is not None):
        return
    raise InputError(
        f"--run {run_dir}: the controller at {address} holds other zero offsets than this "
        f"run pushed ({_later_push(run_dir, push)}); rolling back would overwrite them with "
        f"the ones this run replaced; nothing written. See what it holds: hostpc status "
        f"--robot {address}; roll back anyway (discarding that push) with: "
        f"{rollback_command(run_dir, archive)} --robot {address} {DISCARD_LATER}")


def _later_push(run_dir: Path, push: PushFile) -> str:
    """The later push to the same controller that the run folders beside this one hold
    (a station's runs folder): `a later push: run R at T`, else `a later push, by another
    run or host`."""
    later: tuple[str, str] = ("", push.record.time)
    try:
        since = (run_dir / "push.json").stat().st_mtime
        folders = [p for p in run_dir.resolve().parent.iterdir() if p != run_dir.resolve()]
        files = [f / "push.json" for f in folders if (f / "push.json").is_file()
                 and (f / "push.json").stat().st_mtime >= since]
    except OSError:
        files = []
    for file in files:
        try:
            other = read_push_file(file.parent)
        except InputError:
            continue
        if other.controller == push.controller and other.record.time > later[1]:
            later = (str(file.parent), other.record.time)
    if not later[0]:
        return "a later push, by another run or host"
    return f"a later push: run {later[0]} at {later[1]}"


def _archive_from_journal(args: argparse.Namespace, run_dir: Path, push: PushRecord) -> None:
    """Revise the archived record of a run that stopped after its push (no result.json) and
    was rolled back (`_rolled_back_record`)."""
    archive_run(args, run_dir, EXIT_CODES["ROLLED_BACK"],
                revise=lambda record: _rolled_back_record(record, push))


def _rolled_back_record(record: RunRecord, push: PushRecord) -> RunRecord:
    """The archive record of a run that stopped after its push (no result.json: ERROR)
    and was rolled back: ROLLED_BACK, nothing pushed now, its offsets the push's (the
    previous ones back in the controller)."""
    import dataclasses

    from hostpc.archive.records import push_offsets

    return dataclasses.replace(
        record, verdict="ROLLED_BACK", exit_code=EXIT_CODES["ROLLED_BACK"],
        push_status="rolled_back", offsets=push_offsets(push, rolled_back=True),
        largest_correction_deg=None,
        reason="ROLLED BACK: the run stopped after its push (not verified), and its push "
        "was rolled back: the controller has its previous offsets again")
