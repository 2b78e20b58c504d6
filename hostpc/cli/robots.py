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
from typing import Any

import numpy as np

from hostpc.errors import InputError
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


def _mount(T: Any) -> dict[str, list[float]]:
    """A fixed mount transform as xyz (mm) and roll-pitch-yaw (deg), rounded as printed."""
    from hostpc.kinematics.rotations import matrix_to_rpy

    T = np.asarray(T, dtype=float)
    return {"xyz_mm": [_number(v * 1e3, 3) for v in T[:3, 3]],
            "rpy_deg": [_number(math.degrees(v), 4) for v in matrix_to_rpy(T[:3, :3])]}


def _describe(chain: Chain) -> dict[str, Any]:
    rows = []
    for i in range(chain.n):
        kind = "prismatic" if chain.joint_is_prismatic[i] else "revolute"
        rows.append({
            "joint": i + 1, "type": kind,
            "a_mm": _number(chain.a[i] * 1e3, 6),
            "alpha_deg": _number(math.degrees(chain.alpha[i]), 6),
            "d_mm": _number(chain.d[i] * 1e3, 6),
            "theta_deg": _number(math.degrees(chain.theta[i]), 6),
            "mass_kg": None if chain.mass is None else float(chain.mass[i]),
        })
    description = {"name": chain.name, "convention": chain.convention, "joints": rows,
                   "mounts": chain.has_mounts,
                   "coupled": [{"joint": f + 1, "follows": leader + 1, "multiplier": m,
                                "offset": c} for f, leader, m, c in chain.coupled]}
    if chain.has_mounts:  # T_base_link0 before the first row, T_link_flange after the last
        description["base_mount"] = _mount(chain.T_base_link0)
        description["flange_mount"] = _mount(chain.T_link_flange)
    return description


def run(args: argparse.Namespace) -> int:
    if args.robot is None:
        entries: list[dict[str, Any]] = [
            {"name": n, "joints": get_robot(n).n, "convention": get_robot(n).convention,
             "kind": "chain"} for n in names()]
        entries += [{"name": n, "joints": get_tree(n).n, "convention": None, "kind": "tree",
                     "chains": list(get_tree(n).names)} for n in tree_names()]
        if args.json:
            print(json.dumps(entries, indent=2))
            return 0
        for e in entries:
            detail = (f"{e['joints']} joints, {e['convention'].upper()}" if e["kind"] == "chain"
                      else f"kinematic tree: {', '.join(e['chains'])} ({e['joints']} joints)")
            print(f"{e['name']:16s} {detail}")
        print("Any other robot: a DH/MDH table file (--robot FILE.json, docs/robots.md), an "
              "explicit table in the dataset, or a URDF file (--robot FILE.urdf --base-link "
              "NAME --tip-link NAME).")
        return 0
    description = _describe(resolve_chain(args.robot, args.base_link, args.tip_link))
    if args.json:
        print(json.dumps(description, indent=2))
        return 0
    print(f"{description['name']} ({description['convention'].upper()}"
          f"{', with base and flange mounts' if description['mounts'] else ''})")
    print(f"{'joint':>5s} {'type':>9s} {'a mm':>9s} {'alpha deg':>9s} {'d mm':>9s} "
          f"{'theta deg':>9s} {'mass kg':>8s}")
    for r in description["joints"]:
        mass = "-" if r["mass_kg"] is None else f"{r['mass_kg']:.3f}"
        print(f"{r['joint']:5d} {r['type']:>9s} {_number(r['a_mm'], 2):9.2f} "
              f"{_number(r['alpha_deg'], 3):9.3f} {_number(r['d_mm'], 2):9.2f} "
              f"{_number(r['theta_deg'], 3):9.3f} {mass:>8s}")
    for c in description["coupled"]:
        print(f"joint {c['joint']} follows joint {c['follows']} (<mimic>): q{c['joint']} = "
              f"{c['multiplier']:g} q{c['follows']} + {c['offset']:g}; its zero offset is its "
              "leader's")
    for key, label in (("base_mount", "base mount (T_base_link0, before joint 1)"),
                       ("flange_mount", "flange mount (T_link_flange, after the last joint)")):
        if key in description:
            xyz = ", ".join(f"{_number(v, 2):.2f}" for v in description[key]["xyz_mm"])
            rpy = ", ".join(f"{_number(v, 3):.3f}" for v in description[key]["rpy_deg"])
            print(f"{label}: xyz [{xyz}] mm, rpy [{rpy}] deg")
    return 0


def add_robot_override(parser: argparse.ArgumentParser) -> None:
    """`--robot NAME|FILE.urdf|FILE.json [--base-link L --tip-link L]`: fit a dataset with
    another robot than the one it names (`hostpc fit`, `diagnose`, `predict`)."""
    parser.add_argument("--robot", metavar="NAME|FILE.urdf|FILE.json",
                        help="use this robot instead of the dataset's: a built-in name, a "
                        "URDF file (with --base-link and --tip-link) or a DH/MDH table file "
                        "(docs/robots.md)")
    parser.add_argument("--base-link", help="URDF: the chain's base link")
    parser.add_argument("--tip-link", help="URDF: the chain's tip link (the flange)")


def robot_document(args: argparse.Namespace) -> dict[str, Any] | None:
    """The dataset `robot` object the override options name (None: no override)."""
    robot = getattr(args, "robot", None)
    if not robot:
        if getattr(args, "base_link", None) or getattr(args, "tip_link", None):
            raise InputError("--base-link / --tip-link: only with --robot FILE.urdf")
        return None
    chain = resolve_chain(robot, args.base_link, args.tip_link)  # checks it now: exit 2
    if is_table_file(robot):  # the table itself, in the dataset's units when it is read
        return {"_table": robot, "_n": chain.n}
    if robot.lower().endswith(".urdf"):
        from pathlib import Path

        return {"urdf": str(Path(robot).resolve()), "base_link": args.base_link,
                "tip_link": args.tip_link, "_n": chain.n}
    return {"name": robot, "_n": chain.n}


def load_dataset_with_robot(path: str, robot: dict[str, Any], **options: Any) -> Any:
    """Read the dataset file at `path` with its `robot` replaced by `robot` (from
    `robot_document`); DatasetError naming the file for a bad file or a joint-count
    mismatch. `options` pass through to `dataset_from_dict`."""
    from hostpc.dataset import dataset_from_dict, load_dataset
    from hostpc.errors import DatasetError
    from hostpc.input_files import DATASET, read_input_text

    load_dataset(path)  # the file as it is: readable, valid JSON, a valid dataset
    document = json.loads(read_input_text(path, DATASET, encoding="utf-8-sig"))
    replacement = ({k: v for k, v in robot.items() if not k.startswith("_")}
                   if "_table" not in robot else
                   table_robot_document(robot["_table"], document.get("units")))
    q = [s.get("q") for s in document.get("samples", []) if isinstance(s, dict)]
    if q and isinstance(q[0], list) and len(q[0]) != robot["_n"]:
        raise DatasetError(f"{path}: --robot has {robot['_n']} joints, the samples "
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
