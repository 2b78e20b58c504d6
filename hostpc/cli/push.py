"""`hostpc push FIT.json --robot HOST[:PORT]`: push the zero offsets of an offline fit.

    hostpc fit tracker.json --json > fit.json
    hostpc push fit.json --robot 10.0.0.5 [--out DIR] [--dry-run] [--force]
    hostpc rollback --run DIR                       # undo it

The guard rails, the journal and the rollback are calibrate's (hostpc.calibrate.push,
hostpc.calibrate.offline_push): joints the fit held are left unchanged; the push is refused
(exit 5, as `hostpc calibrate`; 4 is a controller's refusal) if the fit did not converge,
does not explain its data, a correction exceeds --max-correction degrees, the controller is
another robot than the fit's dataset, or it already carries this fit (the ledger
FIT.json.pushes.jsonl beside the fit, hostpc.calibrate.offline_push), or it holds other
offsets than the fit's dataset was measured under (FIT.json `measured_under`, recorded for
a run folder's dataset: hostpc.calibrate.measured_under; a fit without it is pushed with
one `not checked:` line), unless --force.
The intent is written to DIR/push.json before the controller is, so
`hostpc rollback --run DIR` can always undo it; a push cut short (exit 3 link lost, 4 no
reply) names `hostpc status --robot` and that rollback. The controller's offsets are read
back after the write: other ones than pushed, or a reply naming other previous ones than
were read, fail the push (exit 4, hostpc.calibrate.push.PushMismatch: one line with the
joints, both values and the next command). Offsets are printed in degrees.
"""

from __future__ import annotations

import argparse
import asyncio
import dataclasses
import datetime as _dt
import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from hostpc.calibrate.fit_file import parse_fit_text
from hostpc.calibrate.journal import Journal
from hostpc.calibrate.next_commands import rollback_command
from hostpc.calibrate.offline_push import (
    LedgerEntry,
    SavedFit,
    already_pushed,
    ledger_path,
    load_saved_fit,
    record_push,
)
from hostpc.calibrate.push import (
    DEFAULT_MAX_CORRECTION_DEG,
    PushMismatch,
    PushPlan,
    cut_short_line,
    execute_push,
    plan_push,
    same_offsets,
    written_rollback_id,
)
from hostpc.calibrate.summary import EXIT_PUSH_REFUSED
from hostpc.errors import (
    ConnectionFailed,
    InputError,
    ProtocolViolation,
    RequestTimeout,
    ZerocalError,
)
from hostpc.input_files import FIT, read_input_text
from hostpc.robots.base import RobotAdapter
from hostpc.robots.connect import RobotAddress, open_robot, parse_robot
from hostpc.robots.drivers import DEFAULT_DRIVER, DRIVER_NAMES


class PushRefused(ZerocalError):
    """A guard rail refused the push (the message says which and how to override).

    Exit 5, as a refused push in `hostpc calibrate` (EXIT_PUSH_REFUSED); 4 stays for a
    controller refusing a request."""

    exit_code = EXIT_PUSH_REFUSED


def register(subparsers: Any) -> None:
    """Add the `push` subcommand."""
    parser = subparsers.add_parser(
        "push",
        help="push the zero offsets of an offline fit (hostpc fit --json) to a controller",
        description="Write the compensated zero offsets of a saved fit to a controller, with "
        "calibrate's guard rails, journal and rollback.",
    )
    parser.add_argument("fit", metavar="FIT.json", help="output of `hostpc fit DATASET --json`")
    parser.add_argument("--robot", required=True, metavar="HOST[:PORT]",
                        help="controller address")
    parser.add_argument("--driver", choices=DRIVER_NAMES, default=DEFAULT_DRIVER)
    parser.add_argument("--token", help="shared token (default: $ZEROCAL_TOKEN, else the "
                        "simulator's default)")
    parser.add_argument("--timeout", type=float, default=10.0, help="seconds per request")
    parser.add_argument("--out", metavar="DIR", help="push folder (journal, push.json); "
                        "default zerocal-runs/STAMP-push")
    parser.add_argument("--max-correction", type=float, default=DEFAULT_MAX_CORRECTION_DEG,
                        metavar="DEG", help="refuse corrections larger than this (degrees)")
    parser.add_argument("--force", action="store_true", help="push despite a guard rail")
    parser.add_argument("--dry-run", action="store_true", help="plan only; write nothing")
    parser.add_argument("--json", action="store_true", help="print JSON")
    parser.set_defaults(func=run)


def _default_out() -> Path:
    stamp = _dt.datetime.now(_dt.UTC).strftime("%Y%m%dT%H%M%SZ")
    return Path("zerocal-runs") / f"{stamp}-push"


def run(args: argparse.Namespace) -> int:
    if not args.force:
        _refuse_if_not_converged(args.fit)
    saved = load_saved_fit(args.fit)
    address = parse_robot(args.robot)
    if address.sim:
        raise InputError("--robot sim: a simulated controller lives only as long as its run; "
                         "give the address of a running controller")
    if not (args.max_correction > 0):
        raise InputError(f"--max-correction: must be positive, got {args.max_correction}")
    run_dir = Path(args.out) if args.out else _default_out()
    plan, record = asyncio.run(_push(args, saved, address, run_dir))
    document = {
        "fit": str(args.fit),
        "controller": str(address),
        "dry_run": bool(args.dry_run),
        "status": ("refused" if plan.refused else "planned" if args.dry_run else "pushed"),
        "refused": plan.refused,
        "joints": [row.to_dict() for row in plan.joints()],
        "run_dir": None if args.dry_run else str(run_dir),
        "rollback_id": None if record is None else record.rollback_id,
        "measured_under": (None if saved.measured_under is None
                           else saved.measured_under.to_json()),
        "not_checked": UNCHECKED if saved.measured_under is None else None,
    }
    if args.json:
        print(json.dumps(document, indent=2, default=float))
    else:
        _print_plan(plan, args, address, run_dir, record, saved)
    if plan.refused:
        raise PushRefused(f"push refused: {plan.refused}")
    return 0


def _refuse_if_not_converged(fit: str) -> None:
    """PushRefused if FIT.json says its fit did not converge: said before its values are
    checked, whose ranges a fit that did not converge may well exceed (the range's remedy,
    fitting the same dataset again, would give the same fit); the fit's own next command
    (its model_adequacy block) names the dataset."""
    try:
        document = parse_fit_text(read_input_text(fit, FIT, fit), fit)
    except InputError:
        return  # load_saved_fit says what is wrong with the file
    if not isinstance(document, dict) or document.get("converged") is not False:
        return  # checked in full by load_saved_fit
    adequacy = document.get("model_adequacy")
    diagnose = (adequacy.get("next") if isinstance(adequacy, dict)
                and isinstance(adequacy.get("next"), str) else None)
    raise PushRefused(
        f"push refused: {fit}: the fit did not converge ({document.get('message')}): its "
        f"values are not a fit; find why with `{diagnose or 'hostpc diagnose DATASET'}` (do "
        "the dataset's `units` match its numbers?), fit again, then push (--force to push "
        "anyway)")


UNCHECKED = ("not checked: the fit records no controller offsets its dataset was measured "
             "under (the dataset lay outside a run folder), so this push cannot tell whether "
             "the controller already carries its corrections")
"""Said (one line) by a push of such a fit; a fit of a run folder's dataset records them."""


def _print_plan(plan: PushPlan, args: argparse.Namespace, address: RobotAddress,
                run_dir: Path, record: Any, saved: SavedFit) -> None:
    print(f"{'joint':>5s} {'old deg':>11s} {'correction':>11s} {'sigma':>9s} {'new deg':>11s}")
    for j in range(plan.old.size):
        sigma = (f"{math.degrees(plan.sigma[j]):9.5f}" if np.isfinite(plan.sigma[j])
                 else f"{'-':>9s}")
        note = f"  ({plan.notes[j]})" if plan.notes[j] else ""
        print(f"J{j + 1:<4d} {math.degrees(plan.old[j]):11.5f} "
              f"{math.degrees(plan.delta[j]):+11.5f} {sigma} "
              f"{math.degrees(plan.new[j]):11.5f}{note}")
    if plan.refused:
        return
    if saved.measured_under is None:
        print(UNCHECKED)
    if args.dry_run:
        print(f"dry run: nothing written to {address}")
    else:
        print(f"pushed to {address} (rollback id {record.rollback_id}); undo with "
              f"`hostpc rollback --run {run_dir}`")


async def _push(args: argparse.Namespace, saved: SavedFit, address: RobotAddress,
                run_dir: Path) -> tuple[PushPlan, Any]:
    robot = await open_robot(address, args.driver, token=args.token, timeout=args.timeout)
    try:
        offsets = np.asarray(await robot.get_offsets(), float)
        n_fit = len(saved.joint_offsets())
        if n_fit != offsets.size:
            raise InputError(f"{args.fit}: the fit has {n_fit} joint offsets, the controller "
                             f"at {address} has {offsets.size} joints (nothing written); "
                             f"push it to the robot it was measured on: `hostpc push "
                             f"{args.fit} --robot HOST`")
        if not args.force:
            await _check_same_robot_and_not_pushed(robot, saved, args.fit, address, offsets)
        plan = plan_push(saved, offsets, args.max_correction,
                         force=args.force, dataset_file=_dataset_file(args.fit, saved))
        if plan.refused or args.dry_run:
            return plan, None
        run_dir.mkdir(parents=True, exist_ok=True)
        journal = Journal(run_dir)
        journal.write_header({"kind": "offline_push", "fit": str(Path(args.fit).resolve()),
                              "robot": {"address": str(address), "driver": args.driver}})
        entry = LedgerEntry(
            controller=str(address), run_dir=str(run_dir.resolve()),
            time=_dt.datetime.now(_dt.UTC).isoformat(timespec="seconds"),
            before=tuple(plan.old.tolist()), after=tuple(plan.new.tolist()))
        record_push(args.fit, entry)
        try:
            record = await execute_push(robot, plan, run_dir, str(address), journal)
        except PushMismatch as exc:
            _record_held(args.fit, entry, exc.record.held)
            raise
        except (ConnectionFailed, RequestTimeout, ProtocolViolation) as exc:
            raise type(exc)(cut_short_line(exc, run_dir, str(address),
                                           written_rollback_id(journal))) from exc
        return plan, record
    finally:
        await robot.close()


def _record_held(fit: str, entry: LedgerEntry, held: np.ndarray | None) -> None:
    """After a push the controller did not store as asked (PushMismatch): a second ledger
    line with the offsets it holds (`held`, (n,) rad), so that the double-push guard knows
    them as this fit's (unless they are the ones before the push: then the controller
    carries nothing of the fit)."""
    if held is not None and held.size == len(entry.before) and not same_offsets(
            held, entry.before):
        record_push(fit, dataclasses.replace(entry, after=tuple(held.tolist())))


async def _check_same_robot_and_not_pushed(robot: RobotAdapter, saved: SavedFit, fit: str,
                                           address: RobotAddress, offsets: np.ndarray) -> None:
    """Guard rails of an offline push (PushRefused, exit 5, unless --force): the controller
    is the robot the fit's dataset was measured on, and does not already carry this fit."""
    state = await robot.state()
    controller_robot = str(state.robot or "")
    if saved.robot and controller_robot and saved.robot.lower() != controller_robot.lower():
        raise PushRefused(f"push refused: {fit} was measured on a {saved.robot}, the controller "
                          f"at {address} is a {controller_robot}; use --force to push anyway")
    entry = already_pushed(fit, offsets)
    if entry is not None:
        raise PushRefused(
            f"push refused: the controller at {address} already carries this fit (pushed to "
            f"{entry.controller or '?'} at {entry.time or '?'}, "
            f"{ledger_path(fit)}); pushing again would double the corrections; roll back with "
            f"`hostpc rollback --run {entry.run_dir or 'DIR'}` or use --force")
    _refuse_if_measured_under_other_offsets(saved, fit, address, offsets)


def _refuse_if_measured_under_other_offsets(saved: SavedFit, fit: str, address: RobotAddress,
                                            offsets: np.ndarray) -> None:
    """PushRefused (exit 5, unless --force) if FIT.json records the controller's offsets
    its dataset was measured under (a run folder's dataset, measured_under) and the
    controller holds other ones now (`offsets`, (n,) rad): the fit's corrections are
    relative to those; when it holds those plus this fit's corrections (the run's own
    push), pushing them again would double them."""
    measured = saved.measured_under
    if measured is None:
        return
    then = np.asarray(measured.zero_offsets, float)
    if same_offsets(then, offsets):
        return
    run = measured.run
    if then.shape == offsets.shape and same_offsets(
            plan_push(saved, then, force=True).new, offsets):
        raise PushRefused(
            f"push refused: the controller at {address} already carries this fit's "
            f"corrections: its offsets are the ones {run}/{measured.dataset} was measured "
            f"under plus this fit's (its run pushed them); pushing again would double them; "
            f"nothing to push (to undo that push: {rollback_command(run)})")
    labels = [f"J{j + 1}" for j in range(offsets.size)]
    changed = ", ".join(
        f"{labels[j]} {math.degrees(then[j]):+.5f} -> {math.degrees(offsets[j]):+.5f}"
        for j in range(min(then.size, offsets.size))
        if not same_offsets(then[j:j + 1], offsets[j:j + 1]))
    raise PushRefused(
        f"push refused: {fit} was measured under other zero offsets than the controller at "
        f"{address} holds now ({changed or f'{then.size} offsets for {offsets.size} joints'}"
        f" deg; {run}/{measured.dataset}): its corrections are relative to those; measure "
        f"again with: hostpc calibrate --robot {address} (or --force to add them to the "
        "offsets it holds)")


DIAGNOSE = "hostpc diagnose "
LADDER = " --ladder"


def _dataset_file(fit_file: str, saved: SavedFit) -> str:
    """The dataset to diagnose for a refused push: the one beside the fit (a run folder's
    dataset.json), else the one the fit's own next command names (model_adequacy.next,
    `hostpc diagnose DATASET [options] --ladder`, with the options that define its data)."""
    beside = Path(fit_file).parent / "dataset.json"
    if beside.exists():
        return str(beside)
    named = saved.next_command or ""
    if named.startswith(DIAGNOSE) and named.endswith(LADDER):
        return named[len(DIAGNOSE):-len(LADDER)]
    return "DATASET (the dataset the fit was made from)"
