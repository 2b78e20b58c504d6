"""`hostpc robots`: list the built-in robots, or describe one (or a URDF chain).

    hostpc robots                                  # names, joint counts, conventions
    hostpc robots --robot ur10e                    # its table, in mm and degrees
    hostpc robots --robot arm.urdf --base-link base_link --tip-link tool0

A URDF chain is shown as the exact MDH table zerocal converts it to (hostpc.kinematics.urdf),
with each joint's type (revolute or prismatic) and its mass, if the file gives one.
"""

from __future__ import annotations

import argparse
import json
import math
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from hostpc.errors import InputError
from hostpc.json_object import JsonObject
from hostpc.kinematics import Chain, get_robot, names
from hostpc.kinematics.humanoid import get_tree, tree_names
from hostpc.kinematics.table_file import is_table_file, load_table_chain, table_robot_document


def register(subparsers: Any) -> None:
    """Add the `robots` subcommand."""
    parser = subparsers.add_parser(
        "robots",
        help="list the built-in robots or describe one",
        description="List the built-in robots, or print one robot's kinematic table "
        "(a built-in name, or a URDF file with --base-link and --tip-link).",
    )
    parser.add_argument("--robot", metavar="NAME|FILE.urdf|FILE.json",
                        help="robot to describe: a built-in name, a URDF or a DH/MDH table "
                        "file (docs/robots.md)")
    parser.add_argument("--base-link", help="URDF: the chain's base link")
    parser.add_argument("--tip-link", help="URDF: the chain's tip link (the flange)")
    parser.add_argument("--json", action="store_true", help="print JSON instead of text")
    parser.set_defaults(func=run)


def resolve_chain(robot: str, base_link: str | None, tip_link: str | None) -> Chain:
    """A built-in robot by name, a DH/MDH table file's chain (`FILE.json`,
    hostpc.kinematics.table_file) or a URDF file's chain (both links required)."""
    if is_table_file(robot):
        if base_link or tip_link:
            raise InputError(f"--robot {robot}: --base-link / --tip-link are for a URDF; a "
                             "table file is the whole chain")
        return load_table_chain(robot)
    if robot.lower().endswith(".xacro"):
        from hostpc.kinematics.urdf import xacro_refusal

        raise InputError(xacro_refusal(robot))
    if robot.lower().endswith(".urdf"):
        if not base_link or not tip_link:
            raise InputError(f"--robot {robot}: a URDF robot needs --base-link and --tip-link")
        from hostpc.kinematics.urdf import load_urdf_chain

        return load_urdf_chain(robot, base_link, tip_link)
    return get_robot(robot)


def _number(value: float, decimals: int) -> float:
    """``value`` rounded as printed, without a negative zero (``-0.000`` is 0.000)."""
    return round(float(value), decimals) + 0.0


@dataclass(frozen=True)
class Mount:
    """A fixed mount transform as xyz (mm) and roll-pitch-yaw (deg), rounded as printed."""

    xyz_mm: tuple[float, ...]
    rpy_deg: tuple[float, ...]

    @classmethod
    def of(cls, T: np.ndarray) -> Mount:
        """The mount of the (4, 4) transform ``T`` (m)."""
        from hostpc.kinematics.rotations import matrix_to_rpy

        T = np.asarray(T, dtype=float)
        return cls(tuple(_number(v * 1e3, 3) for v in T[:3, 3]),
                   tuple(_number(math.degrees(v), 4) for v in matrix_to_rpy(T[:3, :3])))


@dataclass(frozen=True)
class JointRow:
    """One joint of a chain's table, in mm and degrees (mass in kg, None if not given)."""

    joint: int
    type: str
    a_mm: float
    alpha_deg: float
    d_mm: float
    theta_deg: float
    mass_kg: float | None


@dataclass(frozen=True)
class Coupling:
    """A URDF ``<mimic>`` joint: q[joint] = multiplier q[follows] + offset (1-based)."""

    joint: int
    follows: int
    multiplier: float
    offset: float


@dataclass(frozen=True)
class ChainTable:
    """What `hostpc robots --robot R` shows of a chain: its table, and its base and flange
    mounts when it has them (T_base_link0 before the first row, T_link_flange after the
    last)."""

    name: str
    convention: str
    joints: tuple[JointRow, ...]
    base_mount: Mount | None
    flange_mount: Mount | None
    coupled: tuple[Coupling, ...] = ()

    def to_json(self) -> JsonObject:
        """`hostpc robots --robot R --json`."""
        document: JsonObject = {"name": self.name, "convention": self.convention,
                                "joints": [asdict(row) for row in self.joints],
                                "mounts": self.base_mount is not None,
                                "coupled": [asdict(c) for c in self.coupled]}
        for key, mount in (("base_mount", self.base_mount), ("flange_mount", self.flange_mount)):
            if mount is not None:
                document[key] = {"xyz_mm": list(mount.xyz_mm), "rpy_deg": list(mount.rpy_deg)}
        return document


@dataclass(frozen=True)
class RobotEntry:
    """A built-in robot in `hostpc robots`' list: a chain, or a kinematic tree of chains."""

    name: str
    joints: int
    convention: str | None
    chains: tuple[str, ...] | None = None  # a tree's chains (None: a chain)

    def to_json(self) -> JsonObject:
        """The entry in `hostpc robots --json`."""
        document: JsonObject = {"name": self.name, "joints": self.joints,
                                "convention": self.convention,
                                "kind": "chain" if self.chains is None else "tree"}
        if self.chains is not None:
            document["chains"] = list(self.chains)
        return document


def _describe(chain: Chain) -> ChainTable:
    rows = tuple(JointRow(
        joint=i + 1, type="prismatic" if chain.joint_is_prismatic[i] else "revolute",
        a_mm=_number(chain.a[i] * 1e3, 6), alpha_deg=_number(math.degrees(chain.alpha[i]), 6),
        d_mm=_number(chain.d[i] * 1e3, 6), theta_deg=_number(math.degrees(chain.theta[i]), 6),
        mass_kg=None if chain.mass is None else float(chain.mass[i])) for i in range(chain.n))
    coupled = tuple(Coupling(f + 1, leader + 1, m, c) for f, leader, m, c in chain.coupled)
    base, flange = chain.T_base_link0, chain.T_link_flange
    if not chain.has_mounts or base is None or flange is None:
        return ChainTable(chain.name, chain.convention, rows, None, None, coupled)
    return ChainTable(chain.name, chain.convention, rows, Mount.of(base), Mount.of(flange),
                      coupled)


def run(args: argparse.Namespace) -> int:
    if args.robot is None:
        entries = [RobotEntry(n, get_robot(n).n, get_robot(n).convention) for n in names()]
        entries += [RobotEntry(n, get_tree(n).n, None, tuple(get_tree(n).names))
                    for n in tree_names()]
        if args.json:
            print(json.dumps([e.to_json() for e in entries], indent=2))
            return 0
        for e in entries:
            detail = (f"{e.joints} joints, {str(e.convention).upper()}" if e.chains is None
                      else f"kinematic tree: {', '.join(e.chains)} ({e.joints} joints)")
            print(f"{e.name:16s} {detail}")
        print("Any other robot: a DH/MDH table file (--robot FILE.json, docs/robots.md), an "
              "explicit table in the dataset, or a URDF file (--robot FILE.urdf --base-link "
              "NAME --tip-link NAME).")
        return 0
    table = _describe(resolve_chain(args.robot, args.base_link, args.tip_link))
    if args.json:
        print(json.dumps(table.to_json(), indent=2))
        return 0
    print(f"{table.name} ({table.convention.upper()}"
          f"{', with base and flange mounts' if table.base_mount is not None else ''})")
    print(f"{'joint':>5s} {'type':>9s} {'a mm':>9s} {'alpha deg':>9s} {'d mm':>9s} "
          f"{'theta deg':>9s} {'mass kg':>8s}")
    for r in table.joints:
        mass = "-" if r.mass_kg is None else f"{r.mass_kg:.3f}"
        print(f"{r.joint:5d} {r.type:>9s} {_number(r.a_mm, 2):9.2f} "
              f"{_number(r.alpha_deg, 3):9.3f} {_number(r.d_mm, 2):9.2f} "
              f"{_number(r.theta_deg, 3):9.3f} {mass:>8s}")
    for c in table.coupled:
        print(f"joint {c.joint} follows joint {c.follows} (<mimic>): q{c.joint} = "
              f"{c.multiplier:g} q{c.follows} + {c.offset:g}; its zero offset is its "
              "leader's")
    for mount, label in ((table.base_mount, "base mount (T_base_link0, before joint 1)"),
                         (table.flange_mount,
                          "flange mount (T_link_flange, after the last joint)")):
        if mount is not None:
            xyz = ", ".join(f"{_number(v, 2):.2f}" for v in mount.xyz_mm)
            rpy = ", ".join(f"{_number(v, 3):.3f}" for v in mount.rpy_deg)
            print(f"{label}: xyz [{xyz}] mm, rpy [{rpy}] deg")
    return 0


@dataclass(frozen=True)
class RobotChoice:
    """A robot named on the command line: a built-in ``name``, a ``urdf`` file with its
    chain's end links, or a DH/MDH ``table`` file; ``n_joints``: its chain's joint count."""

    n_joints: int
    name: str | None = None
    urdf: str | None = None
    base_link: str | None = None
    tip_link: str | None = None
    table: str | None = None

    def to_json(self, units: JsonObject | None = None) -> JsonObject:
        """The dataset's ``robot`` object (docs/dataset-format.md); a table file's rows in
        the dataset's ``units`` (its ``units`` object; default SI)."""
        if self.table is not None:
            return table_robot_document(self.table, units)
        if self.urdf is not None:
            return {"urdf": self.urdf, "base_link": self.base_link, "tip_link": self.tip_link}
        return {"name": self.name}


def robot_document(args: argparse.Namespace) -> RobotChoice | None:
    """The robot the override options name (None: no override)."""
    robot = getattr(args, "robot", None)
    if not robot:
        if getattr(args, "base_link", None) or getattr(args, "tip_link", None):
            raise InputError("--base-link / --tip-link: only with --robot FILE.urdf")
        return None
    chain = resolve_chain(robot, args.base_link, args.tip_link)  # checks it now: exit 2
    if is_table_file(robot):  # the table itself, in the dataset's units when it is read
        return RobotChoice(chain.n, table=robot)
    if robot.lower().endswith(".urdf"):
        from pathlib import Path

        return RobotChoice(chain.n, urdf=str(Path(robot).resolve()), base_link=args.base_link,
                           tip_link=args.tip_link)
    return RobotChoice(chain.n, name=robot)


def load_dataset_with_robot(path: str, robot: RobotChoice, **options: Any) -> Any:
    """Read the dataset file at `path` with its `robot` replaced by `robot` (from
    `robot_document`); DatasetError naming the file for a bad file or a joint-count
    mismatch. `options` pass through to `dataset_from_dict`."""
    from hostpc.dataset import dataset_from_dict, load_dataset
    from hostpc.errors import DatasetError
    from hostpc.input_files import DATASET, read_input_text

    load_dataset(path)  # the file as it is: readable, valid JSON, a valid dataset
    document = json.loads(read_input_text(path, DATASET, encoding="utf-8-sig"))
    replacement = robot.to_json(document.get("units"))
    q = [s.get("q") for s in document.get("samples", []) if isinstance(s, dict)]
    if q and isinstance(q[0], list) and len(q[0]) != robot.n_joints:
        raise DatasetError(f"{path}: --robot has {robot.n_joints} joints, the samples "
                           f"{len(q[0])}")
    return dataset_from_dict({**document, "robot": replacement}, str(path), **options)


def load_dataset_as_asked(path: str, args: argparse.Namespace) -> Any:
    """The dataset at ``path`` with the robot of `--robot` (if given) and the kinds of
    `--plugin` (if any): what fit, diagnose and predict read."""
    from hostpc.dataset import load_dataset

    plugins = getattr(args, "plugin", None) or []
    robot = robot_document(args)
    return (load_dataset(path, plugins=plugins) if robot is None
            else load_dataset_with_robot(path, robot, plugins=plugins))
