"""`hostpc rollback`: restore the zero offsets a calibration push replaced.

    hostpc rollback --run DIR [--robot HOST[:PORT]]      the push recorded in DIR/push.json
    hostpc rollback --robot HOST[:PORT] --id ROLLBACK_ID the controller's rollback id

With --run, the controller address defaults to the one the run pushed to, and if the
controller no longer knows the rollback id (it restarted) the previous offsets saved in
push.json are written directly. Offsets are printed in degrees.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from hostpc.errors import InputError
from hostpc.methods.push import read_push_file, rollback
from hostpc.robots.connect import DRIVERS, RobotAddress, open_robot, parse_robot


def register(subparsers: Any) -> None:
    """Add the `rollback` subcommand."""
    parser = subparsers.add_parser(
        "rollback",
        help="restore the zero offsets replaced by a calibration push",
        description="Undo a `hostpc calibrate` push: by run folder (push.json) or rollback id.",
    )
    parser.add_argument("--robot", metavar="HOST[:PORT]",
                        help="controller address (default: the one recorded in the run)")
    parser.add_argument("--driver", choices=DRIVERS, default="zerocal")
    parser.add_argument("--run", metavar="DIR", help="calibration run folder")
    parser.add_argument("--id", dest="rollback_id", help="the controller's rollback id")
    parser.add_argument("--token", help="shared token (default: $ZEROCAL_TOKEN, else the "
                        "simulator's default)")
    parser.add_argument("--timeout", type=float, default=10.0, help="seconds per request")
    parser.add_argument("--json", action="store_true", help="print JSON")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Entry point of `hostpc rollback`; returns the exit code."""
    if bool(args.run) == bool(args.rollback_id):
        raise InputError("give exactly one of --run DIR and --id ROLLBACK_ID")
    previous: np.ndarray | None = None
    address: RobotAddress | None = parse_robot(args.robot) if args.robot else None
    if args.run:
        record = read_push_file(Path(args.run))
        rollback_id = str(record["rollback_id"])
        previous = np.asarray(record.get("previous_offsets"), float)
        if address is None and record.get("controller"):
            address = parse_robot(str(record["controller"]))
    else:
        rollback_id = str(args.rollback_id)
    if address is None:
        raise InputError("--robot HOST[:PORT] is required")
    if address.sim:
        raise InputError("--robot sim: a simulated controller lives only as long as its run; "
                         "give the address of a running controller")
    now, how = asyncio.run(_rollback(address, args, rollback_id, previous))
    matches = previous is None or bool(np.allclose(now, previous, rtol=0.0, atol=1e-12))
    document = {
        "controller": str(address),
        "rollback_id": rollback_id,
        "method": how,
        "offsets_deg": [math.degrees(v) for v in now],
        "previous_offsets_deg": None if previous is None else [math.degrees(v)
                                                               for v in previous],
        "restored": matches,
    }
    if args.json:
        print(json.dumps(document, indent=2))
    else:
        note = ("" if how == "rollback_id"
                else " (id unknown to the controller: wrote the saved offsets)")
        print(f"rolled back {rollback_id} on {address}{note}")
        print("zero offsets now [deg]: " + ", ".join(
            f"J{j + 1} {math.degrees(v):+.5f}" for j, v in enumerate(now)))
        if not matches:
            print("warning: the offsets now differ from the ones saved before the push")
    return 0 if matches else 4


async def _rollback(address: RobotAddress, args: argparse.Namespace, rollback_id: str,
                    previous: np.ndarray | None) -> tuple[np.ndarray, str]:
    robot = await open_robot(address, args.driver, token=args.token, timeout=args.timeout)
    try:
        return await rollback(robot, rollback_id, previous)
    finally:
        await robot.close()
