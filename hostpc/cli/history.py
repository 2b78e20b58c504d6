"""`hostpc history`: archived runs per robot, drift alarms, fleet view (docs/station.md).

Exit codes: 0 no drift alarm, 1 at least one drift alarm, 2 bad input, 3 archive
unreachable.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from hostpc.cli.numbers import finite
from hostpc.errors import InputError


def register(subparsers: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    parser = subparsers.add_parser(
        "history", help="archived runs, zero offsets over time and drift alarms",
        description="Read the results archive: runs per robot, offsets over time with their "
                    "sigmas, drift alarms (exit 1 when any), the fleet's last verdicts.")
    parser.add_argument("--db", required=True, metavar="URL",
                        help="sqlite:///PATH or postgresql://USER@HOST/DB")
    parser.add_argument("--robot", metavar="SERIAL", help="only this robot")
    parser.add_argument("--threshold", type=finite(above=0.0), default=None, metavar="DEG",
                        help="drift alarm when a zero moved more than this (default 0.02 deg)")
    parser.add_argument("--z-limit", type=finite(above=0.0), default=None, metavar="Z",
                        help="... or more than Z sigma of the two fits (default 6)")
    parser.add_argument("--json", action="store_true",
                        help='print {"runs": [...], "drift": [...], "fleet": [...]}')
    parser.add_argument("--html", metavar="FILE", help="write the history page with plots")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from hostpc.archive import drift_findings, open_archive
    from hostpc.archive.drift import DEFAULT_THRESHOLD_DEG, DEFAULT_Z_LIMIT, fleet_summary
    from hostpc.archive.history_page import history_html, local_time

    with open_archive(args.db, create=False) as archive:
        runs = archive.runs(args.robot)
    findings = drift_findings(runs, args.threshold or DEFAULT_THRESHOLD_DEG,
                              args.z_limit or DEFAULT_Z_LIMIT)
    if args.html:
        try:
            Path(args.html).write_text(history_html(
                runs, findings, args.robot, args.threshold or DEFAULT_THRESHOLD_DEG))
        except OSError as exc:
            raise InputError(f"--html {args.html}: cannot write ({exc.strerror})") from None
    if args.json:
        json.dump({"runs": [r.to_json() for r in runs],
                   "drift": [f.to_json() for f in findings],
                   "fleet": [row.to_json() for row in fleet_summary(runs)]},
                  sys.stdout, indent=1, default=str)
        sys.stdout.write("\n")
    else:
        for row in fleet_summary(runs):
            print(f"{row.serial:<20} {row.model:<10} runs {row.runs:>3}  last "
                  f"{row.last_verdict:<10} {local_time(row.last_run)}  "
                  f"largest zero move {row.largest_zero_move_deg:.4f} deg")
        if not runs:
            print("no archived runs" + (f" of {args.robot}" if args.robot else ""))
        for finding in findings:
            print(f"DRIFT {finding.serial} {finding.label}: {finding.reason} "
                  f"(runs {finding.from_run} -> {finding.to_run})")
        if args.html:
            print(f"history page: {args.html}")
    return 1 if findings else 0
