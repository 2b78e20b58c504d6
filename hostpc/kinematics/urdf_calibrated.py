"""The calibrated robot out as a URDF: fitted joint offsets and geometry deltas folded into
the joint origins, so that any URDF consumer (robot_state_publisher, MoveIt, a simulator)
uses the calibrated kinematics without custom code.

This is the convention of ROS ``robot_calibration``: corrected ``<origin xyz rpy>`` of the
movable joints, not ``<calibration rising=...>`` (which URDF consumers ignore for the
kinematics). A joint's zero offset becomes a rotation (revolute) or translation
(prismatic) about/along its axis folded into its origin, so the file's ``q = 0`` is the
calibrated zero; the controller keeps reporting the same joint readings.

How: :func:`hostpc.kinematics.urdf.chain_from_urdf` places MDH frame ``i`` on joint
``i``'s axis, so the URDF joint frame is ``J_i = F_i @ C_i`` with a constant ``C_i`` (it
maps the URDF axis onto ``z``), at ``q = 0``. With the fitted kinematic delta the MDH
frames become ``F'_i`` (forward kinematics at ``q = 0`` with the delta), so ``J'_i = F'_i
@ C_i``, and the joint's new origin is its parent link's corrected pose inverted times
``J'_i``. Fixed joints keep their origins (the corrections land on the movable joints, the
first one absorbing the base side, the last one the flange side), so the product of the new
URDF transforms equals the fitted model's forward kinematics at every ``q`` (exactly: the
motion ``Rz(q)`` / ``Tz(q)`` of an MDH row commutes with the parts that move).
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from hostpc.errors import InputError
from hostpc.kinematics.poses import forward
from hostpc.kinematics.rotations import matrix_to_rpy
from hostpc.kinematics.urdf import _MOVABLE, UrdfRobot, _path, chain_from_urdf

__all__ = ["OriginChange", "calibrated_origins", "calibrated_urdf_text"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class OriginChange:
    """One movable joint's origin before and after calibration (4x4, parent link frame)."""

    joint: str
    before: FloatArray
    after: FloatArray

    @property
    def translation_mm(self) -> float:
        """How far the origin moved (mm)."""
        return float(np.linalg.norm(self.after[:3, 3] - self.before[:3, 3])) * 1e3

    @property
    def rotation_deg(self) -> float:
        """The angle of the rotation between the old and the new origin (deg)."""
        relative = self.before[:3, :3].T @ self.after[:3, :3]
        cosine = max(-1.0, min(1.0, (float(np.trace(relative)) - 1.0) / 2.0))
        return math.degrees(math.acos(cosine))


def calibrated_origins(robot: UrdfRobot, base_link: str, tip_link: str,
                       kin_delta: ArrayLike, source: str = "URDF") -> list[OriginChange]:
    """The corrected origin of every movable joint from ``base_link`` to ``tip_link``.

    Args:
        robot: the parsed URDF the fit used.
        base_link, tip_link: the chain the fit used.
        kin_delta: the fitted kinematic delta, ``(5n,)`` (docs/conventions.md: theta, d, a,
            alpha, beta; joint offsets in the first n), the same for every pose.
    """
    chain = chain_from_urdf(robot, base_link, tip_link, source)
    delta = np.asarray(kin_delta, dtype=np.float64)
    if delta.shape != (5 * chain.n,) or not np.all(np.isfinite(delta)):
        raise InputError(f"kin_delta: expected {5 * chain.n} finite numbers, got shape "
                         f"{delta.shape}")
    zero = np.zeros((1, chain.n))
    nominal = forward(chain, zero).T_base_link[0]
    fitted = forward(chain, zero, delta).T_base_link[0]
    changes: list[OriginChange] = []
    T_nominal = np.eye(4)  # parent link pose at q = 0, nominal and corrected
    T_fitted = np.eye(4)
    i = 0
    for joint in _path(robot, base_link, tip_link, source):
        T_nominal = T_nominal @ joint.origin
        if joint.type in _MOVABLE:
            i += 1
            constant = np.linalg.solve(nominal[i], T_nominal)  # C_i
            joint_frame = fitted[i] @ constant
            after = np.linalg.solve(T_fitted, joint_frame)
            after[3] = (0.0, 0.0, 0.0, 1.0)
            changes.append(OriginChange(joint.name, joint.origin, after))
            T_fitted = joint_frame
        else:
            T_fitted = T_fitted @ joint.origin
    return changes


def _format(value: float) -> str:
    text = f"{value:.12g}"
    return "0" if text == "-0" else text


def calibrated_urdf_text(text: str, changes: list[OriginChange], note: str,
                         source: str = "URDF") -> str:
    """``text`` (the input URDF) with the changed joints' ``<origin>`` replaced, and a
    comment ``note`` (what produced it) after the root; comments are kept."""
    parser = ET.XMLParser(target=ET.TreeBuilder(insert_comments=True))
    try:
        root = ET.fromstring(text, parser=parser)
    except ET.ParseError as exc:
        raise InputError(f"{source}: not valid XML ({exc})") from None
    by_name = {j.get("name"): j for j in root.findall("joint")}
    for change in changes:
        element = by_name.get(change.joint)
        if element is None:
            raise InputError(f"{source}: no joint {change.joint!r}")
        origin = element.find("origin")
        if origin is None:
            origin = ET.Element("origin")
            element.insert(0, origin)
        origin.set("xyz", " ".join(_format(v) for v in change.after[:3, 3]))
        origin.set("rpy", " ".join(_format(v) for v in matrix_to_rpy(change.after[:3, :3])))
    comment = ET.Comment(f" {note} ")
    comment.tail = "\n  "
    root.insert(0, comment)
    body = ET.tostring(root, encoding="unicode")
    return '<?xml version="1.0"?>\n' + body + "\n"

