"""`hostpc fit ... --write-urdf OUT.urdf`: the calibrated robot as a URDF file.

The fitted joint offsets and geometry deltas are folded into the movable joints' origins
(hostpc.kinematics.urdf_calibrated, the convention of ROS robot_calibration), the rest of
the input file is kept, and each changed origin is printed (mm, deg). Only the robot's own
parameters go in: the instrument's frames (world, base, tool, target) are not part of a
URDF. Refused (exit 2) for a robot that is not a URDF, or a model whose kinematic
correction changes from pose to pose (thermal, compliance): one URDF has one geometry.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from hostpc.dataset import RobotDescription
from hostpc.errors import InputError
from hostpc.fitting import FitResult


def add_write_urdf_option(parser: argparse.ArgumentParser) -> None:
    """`--write-urdf OUT.urdf` (hostpc fit)."""
    parser.add_argument("--write-urdf", metavar="OUT.urdf",
                        help="write the calibrated robot (a URDF robot's fitted joint offsets "
                        "and geometry folded into its joint origins) to OUT.urdf")


def check_urdf_robot(robot: RobotDescription, out: str, dataset_arg: str) -> None:
    """Refuse --write-urdf before the fit for a robot that is not read from a URDF."""
    if robot.urdf is None or robot.base_link is None or robot.tip_link is None:
        raise InputError(f"--write-urdf: the robot of {dataset_arg} is not a URDF robot (a "
                         "built-in or table robot has no URDF to correct); give one: hostpc "
                         f"fit {dataset_arg} --robot FILE.urdf --base-link L --tip-link L "
                         f"--write-urdf {out}")


def write_calibrated_urdf(result: FitResult, out: str, dataset_arg: str,
                          json_output: bool) -> None:
    """Write OUT.urdf from the fit of a URDF robot and print which origins changed (to
    stderr under --json, so that stdout stays one JSON document)."""
    from hostpc.kinematics.urdf import parse_urdf
    from hostpc.kinematics.urdf_calibrated import calibrated_origins, calibrated_urdf_text
    from hostpc.model.measurements.terms import kinematic_deltas

    robot = result.problem.dataset.robot
    check_urdf_robot(robot, out, dataset_arg)
    assert robot.urdf is not None and robot.base_link is not None and robot.tip_link
    delta, _, _ = kinematic_deltas(result.problem, result.x, False)
    if delta.shape[0] and np.max(np.abs(delta - delta[0])) > 1e-12:
        varying = [t.effect.name for t in result.problem.terms
                   if t.effect.hook in ("joint", "geometry")
                   and t.effect.name not in ("joint_offsets", "geometry")]
        raise InputError(f"--write-urdf: the fitted kinematic correction changes from pose to "
                         f"pose ({', '.join(varying) or 'a pose-dependent effect'}); a URDF "
                         f"has one geometry: hostpc fit {dataset_arg} --effects "
                         f"joint_offsets,geometry --write-urdf {out}")
    source = robot.urdf
    if Path(out).resolve() == Path(source).resolve():
        raise InputError(f"--write-urdf {out}: that is the input URDF; keep the nominal file "
                         f"and write beside it: hostpc fit {dataset_arg} --write-urdf "
                         f"{Path(out).with_suffix('')}.calibrated.urdf")
    try:
        text = Path(source).read_text(encoding="utf-8")
    except OSError as exc:
        raise InputError(f"{source}: cannot read URDF ({exc.strerror or exc})") from None
    parsed = parse_urdf(text, source)
    changes = calibrated_origins(parsed, robot.base_link, robot.tip_link,
                                 delta[0] if delta.shape[0] else np.zeros(delta.shape[1]),
                                 source)
    note = (f"calibrated by zerocal (hostpc fit {dataset_arg}, effects "
            f"{', '.join(t.effect.name for t in result.problem.terms)}): origins of the "
            f"movable joints {robot.base_link} -> {robot.tip_link} corrected, from {source}")
    try:
        Path(out).write_text(calibrated_urdf_text(text, changes, note.replace("--", "-"),
                                                  source), encoding="utf-8")
    except OSError as exc:
        raise InputError(f"--write-urdf {out}: cannot write ({exc.strerror or exc})") from None
    stream = sys.stderr if json_output else sys.stdout
    print(f"\nwrote {out}: joint origins corrected against {source} "
          "(translation mm, rotation deg):", file=stream)
    for change in changes:
        moved = change.after[:3, 3] - change.before[:3, 3]
        print(f"  {change.joint:20s} {change.translation_mm:9.4f} mm "
              f"(dx {moved[0] * 1e3:+.4f} dy {moved[1] * 1e3:+.4f} dz {moved[2] * 1e3:+.4f})"
              f" {change.rotation_deg:9.5f} deg", file=stream)
    print(f"  use it: hostpc robots --robot {out} --base-link {robot.base_link} --tip-link "
          f"{robot.tip_link}", file=stream)
