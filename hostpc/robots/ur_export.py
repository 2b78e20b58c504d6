"""Export fitted joint zero offsets in the formats UR and ROS users load.

A UR controller has no interface for writing joint zero offsets (its own factory
calibration is read-only), so zerocal applies them on the host (`hostpc.robots.ur`) and
exports them for the other software that drives the robot:

- `kinematics_yaml`: the ur_description / ur_calibration kinematics file
  (`default_kinematics.yaml`, or the calibration yaml `ur_calibration` writes), loaded by
  the ROS / ROS 2 UR driver and `ur_description` (`kinematics_params:=...`)::

      kinematics:
        shoulder:  {x, y, z, roll, pitch, yaw}     # joint 1 origin (shoulder_pan_joint)
        upper_arm: {...}                           # joint 2 (shoulder_lift_joint)
        forearm:   {...}                           # joint 3 (elbow_joint)
        wrist_1:   {...}
        wrist_2:   {...}
        wrist_3:   {...}
        hash: calib_...

- `urdf_snippet`: the same six joints as URDF `<joint>` elements with the corrected
  `<origin xyz rpy>` (ur_description link and joint names), to paste into a robot's URDF;
- `urscript_offsets`: a URScript snippet with the offsets and the two conversions, for
  programs on the pendant.

How an offset enters a joint origin: URDF joint i moves its child by
`T_origin_i @ Rz(q_i)`. With a fitted offset delta_i the true angle is `q_i + delta_i`
(docs/conventions.md), and `T_origin_i @ Rz(q_i + delta_i) = (T_origin_i @ Rz(delta_i)) @
Rz(q_i)`: the corrected origin is the nominal one rotated by delta_i about its own z axis.
ROS then computes the true pose from the angles the controller reports.

The nominal origins come from the robot's DH table (`hostpc.kinematics.Chain`). Standard DH
`T_{i-1,i} = Rz(theta_i + q_i) Tz(d_i) Tx(a_i) Rx(alpha_i) Ry(beta_i)` regroups into
`origin_1 = Tz(d_1) Rz(theta_1)`, `origin_i = Tx(a_{i-1}) Rx(alpha_{i-1}) Ry(beta_{i-1})
Tz(d_i) Rz(theta_i)` and a fixed flange `Tx(a_n) Rx(alpha_n) Ry(beta_n)` (identity for UR);
modified DH `Rx(alpha_i) Ry(beta_i) Tx(a_i) Rz(theta_i + q_i) Tz(d_i)` gives
`origin_i = Rx(alpha_i) Ry(beta_i) Tx(a_i) Tz(d_i) Rz(theta_i)` and an identity flange. For the
UR5e this reproduces ur_description's `default_kinematics.yaml` (z = 0.1625, roll = pi/2,
x = -0.425, ...). rpy is fixed-axis X-Y-Z, `R = Rz(yaw) Ry(pitch) Rx(roll)`, as URDF's.
Lengths metres, angles radians.
"""

from __future__ import annotations

import hashlib
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

from hostpc.errors import InputError
from hostpc.kinematics.chain import Chain
from hostpc.kinematics.rotations import matrix_to_rpy, rot_x, rot_y, rot_z

UR_KINEMATICS_KEYS = ("shoulder", "upper_arm", "forearm", "wrist_1", "wrist_2", "wrist_3")
"""ur_description kinematics yaml keys, joint 1 first."""

UR_URDF_JOINTS = (
    ("shoulder_pan_joint", "base_link_inertia", "shoulder_link"),
    ("shoulder_lift_joint", "shoulder_link", "upper_arm_link"),
    ("elbow_joint", "upper_arm_link", "forearm_link"),
    ("wrist_1_joint", "forearm_link", "wrist_1_link"),
    ("wrist_2_joint", "wrist_1_link", "wrist_2_link"),
    ("wrist_3_joint", "wrist_2_link", "wrist_3_link"),
)
"""(joint, parent link, child link) as in ur_description, joint 1 first."""


@dataclass(frozen=True)
class JointOrigin:
    """A URDF joint origin: xyz (3,) m in the parent link frame, rpy (3,) rad."""

    xyz: np.ndarray
    rpy: np.ndarray

    def matrix(self) -> np.ndarray:
        """(4, 4) transform parent link -> joint frame."""
        T = np.eye(4)
        T[:3, :3] = rot_z(self.rpy[2]) @ rot_y(self.rpy[1]) @ rot_x(self.rpy[0])
        T[:3, 3] = self.xyz
        return T


def _tx(a: float) -> np.ndarray:
    T = np.eye(4)
    T[0, 3] = a
    return T


def _tz(d: float) -> np.ndarray:
    T = np.eye(4)
    T[2, 3] = d
    return T


def _rot(R: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = R
    return T


def _origin(T: np.ndarray) -> JointOrigin:
    return JointOrigin(xyz=T[:3, 3].copy(), rpy=np.asarray(matrix_to_rpy(T[:3, :3]), float))


def _check_offsets(chain: Chain, joint_offsets: np.ndarray | list[float]) -> np.ndarray:
    offsets = np.asarray(joint_offsets, dtype=float).reshape(-1)
    n = chain.a.shape[0]
    if offsets.shape != (n,) or not np.all(np.isfinite(offsets)):
        raise InputError(f"joint_offsets: expected {n} finite values (rad), got {offsets.tolist()}")
    return offsets


def joint_origins(
    chain: Chain, joint_offsets: np.ndarray | list[float] | None = None
) -> tuple[list[JointOrigin], JointOrigin]:
    """Corrected URDF joint origins of `chain` and its fixed flange transform.

    joint_offsets: (n,) rad, the fitted `joint_offsets.q1..qn` (None = nominal).
    Returns ([origin of joint 1..n], flange origin in the last link frame).
    """
    n = chain.a.shape[0]
    offsets = np.zeros(n) if joint_offsets is None else _check_offsets(chain, joint_offsets)
    origins: list[JointOrigin] = []
    if chain.convention == "dh":
        previous = np.eye(4)
        for i in range(n):
            T = previous @ _tz(chain.d[i]) @ _rot(rot_z(chain.theta[i] + offsets[i]))
            origins.append(_origin(T))
            previous = _tx(chain.a[i]) @ _rot(rot_x(chain.alpha[i])) @ _rot(rot_y(chain.beta[i]))
        return origins, _origin(previous)
    for i in range(n):
        T = (
            _rot(rot_x(chain.alpha[i]))
            @ _rot(rot_y(chain.beta[i]))
            @ _tx(chain.a[i])
            @ _tz(chain.d[i])
            @ _rot(rot_z(chain.theta[i] + offsets[i]))
        )
        origins.append(_origin(T))
    return origins, _origin(np.eye(4))


def _clean(value: float) -> float:
    """Round away float noise (|x| < 1e-15 -> 0) so files stay readable."""
    return 0.0 if abs(value) < 1e-15 else float(value)


def _require_six(chain: Chain) -> None:
    if chain.a.shape[0] != 6:
        raise InputError(f"UR export needs a 6-joint robot, {chain.name} has {chain.a.shape[0]}")


def calibration_hash(joint_offsets: np.ndarray | list[float]) -> str:
    """A short, stable id of an offset set (`calib_<12 hex>`), as ur_calibration writes."""
    text = ",".join(f"{v:.12e}" for v in np.asarray(joint_offsets, float).reshape(-1))
    return "calib_" + hashlib.sha256(text.encode()).hexdigest()[:12]


def kinematics_yaml(
    chain: Chain, joint_offsets: np.ndarray | list[float], *, calib_hash: str | None = None
) -> str:
    """The ur_description kinematics yaml (text) with the offsets folded into the origins."""
    _require_six(chain)
    origins, _ = joint_origins(chain, joint_offsets)
    kinematics: dict[str, dict[str, float] | str] = {}
    for key, origin in zip(UR_KINEMATICS_KEYS, origins, strict=True):
        kinematics[key] = {
            "x": _clean(origin.xyz[0]),
            "y": _clean(origin.xyz[1]),
            "z": _clean(origin.xyz[2]),
            "roll": _clean(origin.rpy[0]),
            "pitch": _clean(origin.rpy[1]),
            "yaw": _clean(origin.rpy[2]),
        }
    kinematics["hash"] = calib_hash or calibration_hash(joint_offsets)
    header = (
        f"# {chain.name} kinematics with zerocal joint zero offsets folded into the joint\n"
        "# origins (ur_description format; load with kinematics_params:=<this file>).\n"
        "# joint_offsets (rad, q_true = q_reported + offset): "
        + ", ".join(f"{v:.9g}" for v in np.asarray(joint_offsets, float).reshape(-1))
        + "\n"
    )
    return header + yaml.safe_dump({"kinematics": kinematics}, sort_keys=False)


def urdf_snippet(
    chain: Chain, joint_offsets: np.ndarray | list[float], *, prefix: str = ""
) -> str:
    """URDF `<joint>` elements of the six UR joints with corrected origins (XML text).

    prefix: ur_description's `tf_prefix` put before every joint and link name.
    """
    _require_six(chain)
    origins, flange = joint_origins(chain, joint_offsets)
    robot = ET.Element("robot", {"name": f"{chain.name}_zerocal_joints"})
    robot.append(ET.Comment(
        " zerocal: joint zero offsets folded into the joint origins "
        "(q_true = q_reported + offset) "
    ))
    limits = zip(chain.q_min, chain.q_max, strict=True)
    for (name, parent, child), origin, (lo, hi) in zip(UR_URDF_JOINTS, origins, limits,
                                                        strict=True):
        joint = ET.SubElement(robot, "joint", {"name": prefix + name, "type": "revolute"})
        ET.SubElement(joint, "parent", {"link": prefix + parent})
        ET.SubElement(joint, "child", {"link": prefix + child})
        ET.SubElement(joint, "origin", {
            "xyz": " ".join(repr(_clean(v)) for v in origin.xyz),
            "rpy": " ".join(repr(_clean(v)) for v in origin.rpy),
        })
        ET.SubElement(joint, "axis", {"xyz": "0 0 1"})
        ET.SubElement(joint, "limit", {
            "lower": repr(float(lo)), "upper": repr(float(hi)), "effort": "150.0",
            "velocity": "3.14",
        })
    if not np.allclose(flange.matrix(), np.eye(4), atol=1e-12):
        joint = ET.SubElement(robot, "joint", {"name": prefix + "wrist_3-flange", "type": "fixed"})
        ET.SubElement(joint, "parent", {"link": prefix + "wrist_3_link"})
        ET.SubElement(joint, "child", {"link": prefix + "flange"})
        ET.SubElement(joint, "origin", {
            "xyz": " ".join(repr(_clean(v)) for v in flange.xyz),
            "rpy": " ".join(repr(_clean(v)) for v in flange.rpy),
        })
    ET.indent(robot)
    return ET.tostring(robot, encoding="unicode") + "\n"


def urscript_offsets(joint_offsets: np.ndarray | list[float]) -> str:
    """A URScript snippet: the offsets and conversions between true and reported angles."""
    values = ", ".join(f"{v:.9g}" for v in np.asarray(joint_offsets, float).reshape(-1))
    return (
        "# zerocal joint zero offsets (rad): q_true = q_reported + offset\n"
        f"global zerocal_offsets = [{values}]\n"
        "def zerocal_command(q_true):\n"
        "  # the joint angles to command so that the robot reaches q_true\n"
        "  return [q_true[0] - zerocal_offsets[0], q_true[1] - zerocal_offsets[1], "
        "q_true[2] - zerocal_offsets[2], q_true[3] - zerocal_offsets[3], "
        "q_true[4] - zerocal_offsets[4], q_true[5] - zerocal_offsets[5]]\n"
        "end\n"
        "def zerocal_true(q_reported):\n"
        "  return [q_reported[0] + zerocal_offsets[0], q_reported[1] + zerocal_offsets[1], "
        "q_reported[2] + zerocal_offsets[2], q_reported[3] + zerocal_offsets[3], "
        "q_reported[4] + zerocal_offsets[4], q_reported[5] + zerocal_offsets[5]]\n"
        "end\n"
    )


def write_exports(
    directory: str | Path, chain: Chain, joint_offsets: np.ndarray | list[float],
    *, stem: str | None = None,
) -> dict[str, Path]:
    """Write `<stem>_calibration.yaml`, `<stem>_joints.urdf.xml` and
    `<stem>_offsets.script` into `directory` (stem: default the robot's name, e.g. `ur5e`);
    returns {"yaml"|"urdf"|"urscript": path}."""
    _check_offsets(chain, joint_offsets)
    folder = Path(directory)
    folder.mkdir(parents=True, exist_ok=True)
    stem = chain.name if stem is None else stem
    paths = {
        "yaml": folder / f"{stem}_calibration.yaml",
        "urdf": folder / f"{stem}_joints.urdf.xml",
        "urscript": folder / f"{stem}_offsets.script",
    }
    paths["yaml"].write_text(kinematics_yaml(chain, joint_offsets), encoding="utf-8")
    paths["urdf"].write_text(urdf_snippet(chain, joint_offsets), encoding="utf-8")
    paths["urscript"].write_text(urscript_offsets(joint_offsets), encoding="utf-8")
    return paths
