"""`hostpc import`: write a dataset file from a metrology CSV export (laser tracker, mocap).

    hostpc import poses.csv --method world_pose --robot ur10e \\
        --columns "q=shoulder_pan_joint:wrist_3_joint,x=x1,y=y1,z=z1,\\
                   roll=phix1,pitch=phiy1,yaw=phiz1" -o poses.json

    hostpc import tracker.csv --method world_point --robot arm.urdf \\
        --base-link base_link --tip-link tool0 \\
        --columns "q1=J1,q2=J2,...,x=X,y=Y,z=Z,marker=SMR" --length-unit mm --joint-unit deg

The column mapping is described in ``hostpc.importing.column_map`` and docs/metrology.md.
The output is SI (m, rad). A bad CSV (a mapped column missing from the header, text in a
number, a value outside the dataset's physical range, a missing joint value, an unknown
unit in a header) gets one line naming the row and the column, and exit code 2; repeated
rows, dropped blank rows and a last row without a line end (a file cut while written)
get a warning line each (stderr).
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path
from typing import Any

import numpy as np

from hostpc.cli.robots import RobotChoice, resolve_chain
from hostpc.errors import InputError
from hostpc.importing.column_map import parse_column_map
from hostpc.importing.csv_import import (
    ANGLE_UNITS,
    DECIMALS,
    LENGTH_UNITS,
    ImportOptions,
    document_head,
    read_samples,
)
from hostpc.importing.csv_table import read_csv
from hostpc.importing.frame_guess import guessed_frames
from hostpc.importing.imported import ImportedSamples, write_document
from hostpc.input_files import CSV, check_input_file
from hostpc.kinematics import Chain
from hostpc.kinematics.table_file import is_table_file
from hostpc.model.context import check_coupled_joints


def register(subparsers: Any) -> None:
    """Add the `import` subcommand."""
    parser = subparsers.add_parser(
        "import",
        help="write a dataset from a metrology CSV (world_point, world_pose)",
        description="Read a CSV of joint values and world-frame measurements (laser "
        "tracker, motion capture) and write a zerocal dataset file.",
    )
    parser.add_argument("csv", metavar="CSV", help="the CSV file (first row: column names)")
    parser.add_argument("--method", required=True,
                        help="the dataset's measurement kind: one that reads metrology CSV "
                        "rows (world_point, world_pose)")
    parser.add_argument("--robot", required=True, metavar="NAME|FILE.urdf|FILE.json",
                        help="a built-in robot (hostpc robots), a URDF file or a DH/MDH "
                        "table file (docs/robots.md)")
    parser.add_argument("--base-link", help="URDF: the chain's base link")
    parser.add_argument("--tip-link", help="URDF: the chain's tip link (the flange)")
    parser.add_argument("--columns", required=True, metavar="MAP",
                        help="KEY=COLUMN pairs: q1..qN (or q=FIRST:LAST), x, y, z (or "
                        "marker.NAME=FIRST:LAST per reflector), roll/pitch/yaw or "
                        "qw/qx/qy/qz or rx/ry/rz or e1/e2/e3 (--euler), marker, t, "
                        "temperature, sigma or sx/sy/sz (docs/metrology.md)")
    parser.add_argument("--length-unit", default="m", help=f"{'/'.join(LENGTH_UNITS)}")
    parser.add_argument("--angle-unit", default="rad",
                        help=f"orientation columns: {'/'.join(ANGLE_UNITS)}")
    parser.add_argument("--euler", metavar="SEQ-intrinsic|SEQ-extrinsic",
                        help="the convention of the e1, e2, e3 columns, e.g. zyx-intrinsic "
                        "(SEQ: xyz, zyx, zyz, ... any of the twelve)")
    parser.add_argument("--decimal", default="auto", choices=DECIMALS,
                        help="decimal mark of the numbers (auto: a comma when the fields are "
                        "separated by ';' or tabs and the first row writes 1,5)")
    parser.add_argument("--joint-unit", default="rad",
                        help=f"revolute joint columns: {'/'.join(ANGLE_UNITS)}")
    parser.add_argument("--prismatic-unit", default=None,
                        help=f"prismatic joint columns: {'/'.join(LENGTH_UNITS)} (default: "
                        "the --length-unit)")
    parser.add_argument("--sigma", type=float, default=None,
                        help="position sigma, length unit (default 0.1 mm)")
    parser.add_argument("--sigma-angle", type=float, default=None,
                        help="orientation sigma, angle unit (default 1 mrad)")
    parser.add_argument("--known", default="", help="comma-separated frames to hold "
                        "(world, markers, tool)")
    parser.add_argument("--no-guess", action="store_true",
                        help="leave the nominal world and tool/marker frames at zero instead "
                        "of estimating them from the data (hostpc.importing.frame_guess)")
    parser.add_argument("-o", "--output", required=True, help="dataset file to write")
    parser.set_defaults(func=run)


def _robot(args: argparse.Namespace, output: Path) -> tuple[RobotChoice, Chain]:
    """The dataset's robot (a URDF path relative to the dataset file, a table file's rows in
    SI) and its chain."""
    chain = resolve_chain(args.robot, args.base_link, args.tip_link)
    if is_table_file(args.robot):  # the table itself: the dataset is SI
        return RobotChoice(chain.n, table=args.robot), chain
    if args.robot.lower().endswith(".urdf"):
        relative = os.path.relpath(Path(args.robot).resolve(), output.resolve().parent)
        return RobotChoice(chain.n, urdf=relative, base_link=args.base_link,
                           tip_link=args.tip_link), chain
    return RobotChoice(chain.n, name=args.robot), chain


def _method_frames(method: str) -> tuple[str, ...]:
    """The frames a dataset of ``method`` can mark known (its measurement model's)."""
    from hostpc.model.measurements.registry import measurement_model

    return tuple(measurement_model(method).default_frames)


def run(args: argparse.Namespace) -> int:
    from hostpc.dataset.kind_registry import csv_row_kinds

    if args.method not in csv_row_kinds():
        raise InputError(f"--method {args.method!r}: not read from a metrology CSV (known: "
                         f"{', '.join(csv_row_kinds())})")
    for option, value, units in (("--length-unit", args.length_unit, LENGTH_UNITS),
                                 ("--angle-unit", args.angle_unit, ANGLE_UNITS),
                                 ("--joint-unit", args.joint_unit, ANGLE_UNITS),
                                 ("--prismatic-unit", args.prismatic_unit, LENGTH_UNITS)):
        if value is not None and value not in units:
            raise InputError(f"{option}: unknown unit {value!r} (expected one of "
                             f"{', '.join(units)})")
    for option, value in (("--sigma", args.sigma), ("--sigma-angle", args.sigma_angle)):
        if value is not None and not value > 0:
            raise InputError(f"{option}: must be positive, got {value}")
    known = tuple(k.strip() for k in args.known.split(",") if k.strip())
    frames = _method_frames(args.method)
    unknown = [k for k in known if k not in frames]
    if unknown:
        raise InputError(f"--known: {', '.join(map(repr, unknown))} is not a frame of "
                         f"{args.method} (its frames: {', '.join(frames)})")
    output = Path(args.output)
    robot, chain = _robot(args, output)
    prismatic = tuple(bool(p) for p in chain.joint_is_prismatic)
    check_input_file(args.csv, CSV)  # a regular file (no FIFO, device) within the CSV limit
    options = ImportOptions(
        method=args.method, robot=robot.to_json(), prismatic=prismatic,
        length_unit=args.length_unit, angle_unit=args.angle_unit, joint_unit=args.joint_unit,
        prismatic_unit=args.prismatic_unit,
        sigma=args.sigma if args.sigma is not None else 1e-4 / LENGTH_UNITS[args.length_unit],
        sigma_angle=args.sigma_angle, known=known, decimal=args.decimal, euler=args.euler)
    samples, derived = _read_csv_file(Path(args.csv), args, chain, options,
                                      _joint_names(args) if robot.urdf else ())
    for warning in samples.warnings:
        print(f"warning: {warning}", file=sys.stderr)
    for follower, leader, multiplier, offset in chain.coupled:
        if follower in derived:  # left out of --columns: computed from its leader
            samples.q[:, follower] = multiplier * samples.q[:, leader] + offset
            print(f"q{follower + 1} follows q{leader + 1} (<mimic>: {multiplier:g} x leader "
                  f"+ {offset:g}): computed from it")
    _warn_short_prismatic_travel(samples, prismatic, args)
    _warn_unit_slip(samples, chain, args)
    check_coupled_joints(chain, samples.q, (str(Path(args.robot).resolve()), args.base_link,
                                            args.tip_link) if robot.urdf else None)
    head = document_head(samples, options)
    if not args.no_guess:
        head["frames"] = guessed_frames(samples, chain, head["frames"])
    try:
        with output.open("w", encoding="utf-8") as out:
            write_document(out, head, samples)
    except OSError as exc:
        output.unlink(missing_ok=True)
        raise InputError(f"{output}: cannot write ({exc.strerror or exc})") from None
    print(f"wrote {output}: {len(samples)} samples, method {args.method}, "
          f"robot {robot.name or robot.urdf or robot.table}")
    return 0


SHORT_PRISMATIC_TRAVEL_M = 1e-3
"""A prismatic joint whose column spans less than this (m) after conversion is likely
read in the wrong unit (a lift's travel in m read as mm)."""


def _warn_short_prismatic_travel(samples: ImportedSamples, prismatic: tuple[bool, ...],
                                 args: argparse.Namespace) -> None:
    """One warning line (stderr) per prismatic joint whose column spans under 1 mm after
    conversion, naming the unit it was read in and the option that sets it."""
    unit = args.prismatic_unit or args.length_unit
    for j, is_prismatic in enumerate(prismatic):
        if not is_prismatic or not len(samples):
            continue
        span = float(np.ptp(samples.q[:, j]))
        if span < SHORT_PRISMATIC_TRAVEL_M:
            print(f"warning: prismatic joint q{j + 1} spans only {span * 1e3:.3g} mm read "
                  f"in {unit}: a unit mix-up? its unit is --prismatic-unit "
                  f"{'/'.join(LENGTH_UNITS)} (default: the --length-unit)", file=sys.stderr)


def _warn_unit_slip(samples: ImportedSamples, chain: Chain, args: argparse.Namespace) -> None:
    """One warning line (stderr) when the measured points spread ten times less or more
    than the nominal robot's flange over the same joint values (hostpc.cli.units_hint): it
    names the declared units, the ones the numbers suggest and the import command that reads
    them so."""
    from hostpc.cli.units_hint import unit_slip, unit_slip_sentence

    slip = unit_slip(chain, samples.q, samples.p, args.length_unit, args.joint_unit,
                     args.prismatic_unit)
    if slip is None:
        _warn_mirrored_axes(samples, chain, args)
        return
    sentence = unit_slip_sentence(slip, "--length-unit", "--joint-unit", chain.name)
    units = slip.suggested_units
    if units is not None:
        sentence += f": {_import_command(args, *units)}"
    print(f"warning: {sentence}", file=sys.stderr)


def _warn_mirrored_axes(samples: ImportedSamples, chain: Chain,
                        args: argparse.Namespace) -> None:
    """One warning line (stderr) when the measured points fit the nominal robot far better
    with two axes exchanged (hostpc.cli.units_hint.mirrored_axes), with the import command
    that exchanges their columns (when --columns maps them one by one)."""
    from hostpc.cli.units_hint import mirrored_axes, mirrored_axes_sentence

    mirror = mirrored_axes(chain, samples.q, samples.p, args.method, samples.marker_index)
    if mirror is None:
        return
    sentence = mirrored_axes_sentence(mirror, chain.name)
    columns = _exchanged(args.columns, *mirror.axes)
    fix = (_import_command(args, args.length_unit, args.joint_unit, columns)
           if columns is not None else f"exchange the {mirror.axes[0]} and {mirror.axes[1]} "
           "columns in --columns")
    print(f"warning: {sentence}: {fix}", file=sys.stderr)


def _exchanged(columns: str, a: str, b: str) -> str | None:
    """``--columns`` with the columns of keys ``a`` and ``b`` exchanged; None unless both
    are mapped one by one."""
    parts = [part.strip() for part in columns.split(",")]
    keys = [part.partition("=")[0].strip() for part in parts]
    if a not in keys or b not in keys:
        return None
    i, j = keys.index(a), keys.index(b)
    parts[i], parts[j] = (f"{a}={parts[j].partition('=')[2].strip()}",
                          f"{b}={parts[i].partition('=')[2].strip()}")
    return ",".join(parts)


_OPTIONS = (("method", "--method"), ("robot", "--robot"), ("base_link", "--base-link"),
            ("tip_link", "--tip-link"), ("columns", "--columns"),
            ("length_unit", "--length-unit"), ("angle_unit", "--angle-unit"),
            ("euler", "--euler"), ("decimal", "--decimal"), ("joint_unit", "--joint-unit"),
            ("prismatic_unit", "--prismatic-unit"), ("sigma", "--sigma"),
            ("sigma_angle", "--sigma-angle"), ("known", "--known"))
"""The import's options with a value, in the order of its help: the command rebuilt."""
_DEFAULTS = {"angle_unit": "rad", "decimal": "auto", "known": ""}
"""Values left out of the rebuilt command (the parser's defaults)."""


def _import_command(args: argparse.Namespace, length_unit: str, joint_unit: str,
                    columns: str | None = None) -> str:
    """This import's command with the length and joint units (and ``columns``, if given)
    replaced; --sigma (in the length unit) converted so that it states the same noise."""
    import shlex

    values = {**vars(args), "length_unit": length_unit, "joint_unit": joint_unit,
              "columns": columns or args.columns}
    if args.sigma is not None:
        same_noise = args.sigma * LENGTH_UNITS[args.length_unit] / LENGTH_UNITS[length_unit]
        values["sigma"] = float(f"{same_noise:.6g}")
    words = ["hostpc", "import", shlex.quote(args.csv)]
    for dest, option in _OPTIONS:
        value = values.get(dest)
        if value is None or value == _DEFAULTS.get(dest):
            continue
        words += [option, shlex.quote(f"{value:g}" if isinstance(value, float) else str(value))]
    if args.no_guess:
        words.append("--no-guess")
    return " ".join([*words, "-o", shlex.quote(args.output)])


def _joint_names(args: argparse.Namespace) -> tuple[str, ...]:
    """The URDF's names of the chain's movable joints, in joint order."""
    from hostpc.kinematics.urdf import chain_joints  # xml.etree: only for a URDF

    return tuple(j.name for j in chain_joints(args.robot, args.base_link, args.tip_link))


def _read_csv_file(path: Path, args: argparse.Namespace, chain: Chain,
                   options: ImportOptions, joint_names: tuple[str, ...] = ()
                   ) -> tuple[ImportedSamples, tuple[int, ...]]:
    """The samples of the CSV at ``path``, read row by row from the open file (never the
    whole text at once: a tracker export may have millions of rows), and the coupled
    joints --columns left out (0-based; their values are still to be computed).
    joint_names: the robot's (a URDF's), by which a joint range is read (column_map)."""
    followers = {f + 1: leader + 1 for f, leader, _, _ in chain.coupled}
    try:
        with path.open(encoding="utf-8-sig", newline="") as stream:
            table = read_csv(stream, args.csv)
            mapping = parse_column_map(args.columns, table.header.columns, chain.n,
                                       args.method, args.csv, followers, joint_names)
            for note in mapping.notes:
                print(f"note: {note}")
            return read_samples(table, mapping, options), mapping.derived
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{args.csv}: cannot read ({getattr(exc, 'strerror', None) or exc})"
                         ) from None
