"""Robots read from a URDF file: the chain from ``base_link`` to ``tip_link`` as an MDH table.

A URDF joint places its child link at ``T_parent_child = T_origin @ M(q)``, where
``T_origin`` is the joint's ``origin`` (xyz, rpy) and ``M(q)`` a rotation about (revolute,
continuous) or a translation along (prismatic) the unit ``axis``, in the joint frame. Fixed
joints are folded into the next movable joint's origin (or into the flange mount after the
last one). Only the kinematic and inertial tags are read: meshes, visual and collision
elements may be missing.

The chain is converted *exactly* to a modified-DH (Craig) :class:`Chain` with two fixed
mounts: frame ``i`` has ``z`` along joint ``i``'s axis and ``x`` along the common normal to
the next axis (for parallel axes the normal through the previous normal's foot, so
``d = 0``); ``T_base_link0`` places frame 0 (frame 1 at ``q = 0``) in ``base_link``, and
``T_link_flange`` places ``tip_link`` in frame ``n``. Forward kinematics, the analytic
screws, gravity, and every effect (joint offsets, the geometry effect's ``d, a, alpha``
and Hayati ``beta`` per joint) then work on URDF robots unchanged; the geometry effect's
parameters are the minimal (identifiable) set of deltas of each joint's origin, and the
fit names any remaining unidentifiable combination. Link masses and centres of mass come
from the ``inertial`` tags (links fixed to a moving link, on the chain or off it, such as a
wrist camera, are merged into it).

A ``<mimic>`` joint on the chain is a coupled joint (``Chain.coupled``: ``q = multiplier *
q_leader + offset``, its leader a movable joint of the same chain); one whose leader is off
the chain is refused.

The parser is ``xml.etree`` from the standard library: the kinematic subset of URDF is
small, and the PyPI parsers either pull a mesh stack (yourdfpy needs ``trimesh[easy]``) or
are unmaintained (urdf-parser-py, last release 2020).
"""

from __future__ import annotations

import math
import os
import xml.etree.ElementTree as ET
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from hostpc.errors import InputError
from hostpc.input_files import URDF, read_input_text
from hostpc.kinematics.chain import Chain
from hostpc.kinematics.rotations import pose_to_transform
from hostpc.kinematics.tables import chain_from_table

__all__ = ["UrdfJoint", "UrdfRobot", "chain_from_urdf", "load_urdf_chain", "parse_urdf",
           "xacro_refusal"]

FloatArray = NDArray[np.float64]

_MOVABLE = {"revolute": "revolute", "continuous": "revolute", "prismatic": "prismatic"}
_PARALLEL = 1e-9
"""|sin| of the angle between two axes below which they count as parallel here."""


@dataclass(frozen=True)
class UrdfJoint:
    """One URDF joint: ``T_parent_child = origin @ M(q)`` (see the module docstring)."""

    name: str
    type: str
    parent: str
    child: str
    origin: FloatArray  # (4, 4)
    axis: FloatArray  # (3,), unit, in the joint frame
    lower: float
    upper: float
    mimic: str | None = None  # the joint this one follows (<mimic joint=...>), if any
    multiplier: float = 1.0  # <mimic multiplier=...>: q = multiplier * q_leader + offset
    offset: float = 0.0  # <mimic offset=...>


@dataclass(frozen=True)
class UrdfRobot:
    """The parsed kinematic and inertial content of a URDF file.

    Attributes:
        name: the ``robot`` element's name.
        joints: joint name -> joint.
        inertials: link name -> ``(mass kg, centre of mass xyz in the link frame m)``.
    """

    name: str
    joints: dict[str, UrdfJoint]
    inertials: dict[str, tuple[float, FloatArray]]
    links: tuple[str, ...]


MAX_ORIGIN_M = 100.0
"""Largest joint or inertial origin coordinate (m): no robot is larger (as a dataset's
positions, hostpc.dataset.validation.MAX_POSITION_M)."""
MAX_ORIGIN_RAD = 100.0
"""Largest origin roll, pitch or yaw (rad)."""
MAX_LINK_MASS_KG = 1e6
"""Largest link mass (kg): no robot link weighs more; a larger value is a typo."""


def _floats(text: str | None, count: int, where: str, default: list[float]) -> list[float]:
    if text is None:
        return default
    parts = text.split()
    try:
        values = [float(v) for v in parts]
    except ValueError:
        raise InputError(f"{where}: expected {count} numbers, got {text!r}") from None
    if len(values) != count or not all(math.isfinite(v) for v in values):
        raise InputError(f"{where}: expected {count} finite numbers, got {text!r}")
    return values


def _origin(element: ET.Element, where: str) -> FloatArray:
    origin = element.find("origin")
    if origin is None:
        return np.eye(4)
    xyz = _floats(origin.get("xyz"), 3, f"{where} origin xyz", [0.0, 0.0, 0.0])
    rpy = _floats(origin.get("rpy"), 3, f"{where} origin rpy", [0.0, 0.0, 0.0])
    for name, values, limit, unit in (("xyz", xyz, MAX_ORIGIN_M, "m"),
                                      ("rpy", rpy, MAX_ORIGIN_RAD, "rad")):
        if any(abs(v) > limit for v in values):
            raise InputError(f"{where} origin {name}: {origin.get(name)!r} is outside the "
                             f"physical range (|value| <= {limit:g} {unit})")
    return pose_to_transform(np.array(xyz), np.array(rpy))


def parse_urdf(text: str, source: str = "URDF") -> UrdfRobot:
    """Parse URDF text; InputError naming ``source`` and the element on malformed input."""
    try:
        root = ET.fromstring(text)
    except ET.ParseError as exc:
        if "xacro:" in text:  # a xacro prefix used without its namespace declaration
            raise InputError(xacro_refusal(source)) from None
        raise InputError(f"{source}: not valid XML ({exc})") from None
    if root.tag != "robot":
        raise InputError(f"{source}: the root element is <{root.tag}>, expected <robot>")
    _refuse_xacro(root, source)
    links: list[str] = []
    inertials: dict[str, tuple[float, FloatArray]] = {}
    for link in root.findall("link"):
        name = link.get("name")
        if not name:
            raise InputError(f"{source}: a <link> has no name")
        links.append(name)
        inertial = link.find("inertial")
        if inertial is None:
            continue
        mass_el = inertial.find("mass")
        where = f"{source}: link {name!r} inertial"
        mass = _floats(None if mass_el is None else mass_el.get("value"), 1, f"{where} mass",
                       [0.0])[0]
        if not 0 <= mass <= MAX_LINK_MASS_KG:
            raise InputError(f"{where} mass: must be in [0, {MAX_LINK_MASS_KG:g}] kg, "
                             f"got {mass}")
        inertials[name] = (mass, _origin(inertial, where)[:3, 3])
    joints: dict[str, UrdfJoint] = {}
    for joint in root.findall("joint"):
        name = joint.get("name") or ""
        where = f"{source}: joint {name!r}"
        kind = joint.get("type") or ""
        parent, child = joint.find("parent"), joint.find("child")
        if not name or parent is None or child is None:
            raise InputError(f"{where}: needs a name, <parent link=...> and <child link=...>")
        axis_element = joint.find("axis")
        axis_text = None if axis_element is None else axis_element.get("xyz")
        axis: FloatArray = np.array(_floats(axis_text, 3, f"{where} axis", [1.0, 0.0, 0.0]),
                                    dtype=np.float64)
        norm = float(np.linalg.norm(axis))
        if not math.isfinite(norm):
            raise InputError(f"{where} axis: {axis_text!r} is too large a vector")
        if kind in _MOVABLE and norm < 1e-12:
            raise InputError(f"{where} axis: zero vector")
        limit = joint.find("limit")
        lower, upper = -2.0 * math.pi, 2.0 * math.pi
        if kind in ("revolute", "prismatic") and limit is not None:
            lower = _floats(limit.get("lower"), 1, f"{where} limit lower", [lower])[0]
            upper = _floats(limit.get("upper"), 1, f"{where} limit upper", [upper])[0]
            if lower > upper:
                raise InputError(f"{where} limit: lower {lower} > upper {upper}")
        mimic = joint.find("mimic")
        multiplier, offset = (1.0, 0.0) if mimic is None else (
            _floats(mimic.get("multiplier"), 1, f"{where} mimic multiplier", [1.0])[0],
            _floats(mimic.get("offset"), 1, f"{where} mimic offset", [0.0])[0])
        joints[name] = UrdfJoint(
            name=name, type=kind, parent=parent.get("link") or "", child=child.get("link") or "",
            origin=_origin(joint, where), axis=axis / max(norm, 1e-300),
            lower=lower, upper=upper, mimic=_mimicked(joint), multiplier=multiplier,
            offset=offset,
        )
    _check_tree(links, joints, source)
    return UrdfRobot(name=root.get("name") or "urdf", joints=joints, inertials=inertials,
                     links=tuple(links))


_XACRO_NAMESPACE = "{http://www.ros.org/wiki/xacro}"


def _refuse_xacro(root: ET.Element, source: str) -> None:
    """A xacro file (macros, properties, includes) is not URDF until ROS's ``xacro`` has
    expanded it; its elements carry the xacro namespace."""
    if any(element.tag.startswith(_XACRO_NAMESPACE) or element.tag.startswith("xacro:")
           for element in root.iter() if isinstance(element.tag, str)):
        raise InputError(xacro_refusal(source))


def xacro_refusal(source: str) -> str:
    """The one line refusing a xacro file, with the command that expands it
    (``arm.urdf.xacro`` / ``arm.xacro`` -> ``arm.urdf``)."""
    stem = source[:-len(".xacro")] if source.endswith(".xacro") else source
    target = stem if stem.endswith(".urdf") else stem + ".urdf"
    return (f"{source}: a xacro file, not plain URDF; expand it first (ROS xacro), then use "
            f"the .urdf: xacro {source} > {target}")


def _mimicked(joint: ET.Element) -> str | None:
    mimic = joint.find("mimic")
    return None if mimic is None else (mimic.get("joint") or "?")


def _check_tree(links: list[str], joints: dict[str, UrdfJoint], source: str) -> None:
    """A URDF robot is a tree: unique link names, every joint between declared links, each
    link the child of at most one joint, and no loop (URDF cannot express closed chains)."""
    seen: set[str] = set()
    for link in links:
        if link in seen:
            raise InputError(f"{source}: link {link!r} is declared twice")
        seen.add(link)
    parent_joint: dict[str, str] = {}
    for joint in joints.values():
        for role, link in (("parent", joint.parent), ("child", joint.child)):
            if link not in seen:
                raise InputError(f"{source}: joint {joint.name!r} {role} link {link!r} is not "
                                 "a declared <link>")
        if joint.parent == joint.child:
            raise InputError(f"{source}: joint {joint.name!r} joins link {joint.child!r} to "
                             "itself")
        if joint.child in parent_joint:
            raise InputError(f"{source}: link {joint.child!r} is the child of two joints "
                             f"({parent_joint[joint.child]!r} and {joint.name!r}); a URDF "
                             "robot must be a tree")
        parent_joint[joint.child] = joint.name
    parent_of = {j.child: j.parent for j in joints.values()}
    for start in parent_of:
        link, steps = start, 0
        while link in parent_of:
            link, steps = parent_of[link], steps + 1
            if steps > len(parent_of):
                raise InputError(f"{source}: the joints form a loop through link {start!r}; "
                                 "a URDF robot must be a tree")


def _path(robot: UrdfRobot, base_link: str, tip_link: str, source: str) -> list[UrdfJoint]:
    """The joints from ``base_link`` to ``tip_link``, base first."""
    for link, role in ((base_link, "base_link"), (tip_link, "tip_link")):
        if link not in robot.links:
            raise InputError(f"{source}: {role} {link!r} is not a link of the robot "
                             f"(links: {', '.join(robot.links)})")
    by_child = {j.child: j for j in robot.joints.values()}
    path: list[UrdfJoint] = []
    link = tip_link
    while link != base_link:
        joint = by_child.get(link)
        if joint is None:
            raise InputError(f"{source}: tip_link {tip_link!r} does not hang from base_link "
                             f"{base_link!r}")
        if joint.type not in _MOVABLE and joint.type != "fixed":
            raise InputError(f"{source}: joint {joint.name!r} has type {joint.type!r}; only "
                             "revolute, continuous, prismatic and fixed are supported")
        path.append(joint)
        link = joint.parent
        if len(path) > len(robot.joints):
            raise InputError(f"{source}: the joints form a loop")
    on_path = {j.name: j for j in path if j.type in _MOVABLE}
    for joint in path[::-1]:  # a coupled joint needs its leader on the chain (base first)
        if joint.mimic is None or joint.type not in _MOVABLE:
            continue
        leader = on_path.get(joint.mimic)
        if leader is None or leader.mimic is not None:
            why = ("itself follows another joint" if leader is not None
                   else f"is not a movable joint between {base_link} and {tip_link}")
            raise InputError(f"{source}: joint {joint.name!r} mimics joint {joint.mimic!r} "
                             f"(<mimic>), which {why}; zerocal couples a joint only to a "
                             "leader on the same chain: end the chain before it, e.g. hostpc "
                             f"robots --robot {source} --base-link {base_link} --tip-link "
                             f"{joint.parent}")
    return path[::-1]


def _common_normal(p1: FloatArray, u1: FloatArray, p2: FloatArray, u2: FloatArray,
                   x_prev: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Foot on line 1, foot on line 2 and unit direction of their common normal.

    For parallel lines the normal runs from ``p1`` (so that ``d = 0``); for coincident
    lines the direction is ``x_prev`` made perpendicular to ``u1``."""
    w = np.cross(u1, u2)
    s = float(np.linalg.norm(w))
    if s > _PARALLEL:
        r = p2 - p1
        t1 = float(np.dot(np.cross(r, u2), w)) / s**2
        t2 = float(np.dot(np.cross(r, u1), w)) / s**2
        foot1, foot2 = p1 + t1 * u1, p2 + t2 * u2
    else:
        foot1 = p1
        r = p2 - p1
        foot2 = p1 + r - np.dot(r, u2) * u2
    gap = foot2 - foot1
    distance = float(np.linalg.norm(gap))
    if distance > 1e-12:
        x = gap / distance
    elif s > _PARALLEL:
        x = w / s
    else:
        x = x_prev - np.dot(x_prev, u1) * u1
        x = x / np.linalg.norm(x)
    return foot1, foot2, x


def _frame(origin: FloatArray, z: FloatArray, x: FloatArray) -> FloatArray:
    T = np.eye(4)
    T[:3, 0], T[:3, 2] = x, z
    T[:3, 1] = np.cross(z, x)
    T[:3, 3] = origin
    return T


def _any_perpendicular(z: FloatArray) -> FloatArray:
    x = np.array([1.0, 0.0, 0.0]) - z[0] * z
    if np.linalg.norm(x) < 1e-6:
        x = np.array([0.0, 1.0, 0.0]) - z[1] * z
    return x / np.linalg.norm(x)


def chain_from_urdf(robot: UrdfRobot, base_link: str, tip_link: str,
                    source: str = "URDF") -> Chain:
    """The MDH chain (with mounts) of ``robot`` from ``base_link`` to ``tip_link``."""
    path = _path(robot, base_link, tip_link, source)
    movable = [j for j in path if j.type in _MOVABLE]
    if not movable:
        raise InputError(f"{source}: no movable joint between {base_link!r} and {tip_link!r}")
    # Joint frames and moving links at q = 0, in base_link coordinates.
    T = np.eye(4)
    joint_frames: list[FloatArray] = []
    link_owner: dict[str, int] = {}  # link -> index of the movable joint that carries it
    link_pose: dict[str, FloatArray] = {base_link: np.eye(4)}
    owner = -1
    for joint in path:
        T = T @ joint.origin
        if joint.type in _MOVABLE:
            joint_frames.append(T.copy())
            owner += 1
        link_pose[joint.child] = T.copy()
        if owner >= 0:
            link_owner[joint.child] = owner
    T_base_tip = T
    _attach_fixed_links(robot, link_owner, link_pose)
    axes = [F[:3, :3] @ j.axis for F, j in zip(joint_frames, movable, strict=True)]
    points = [F[:3, 3] for F in joint_frames]
    n = len(movable)
    # MDH frames 1..n (Craig): z_i along axis i, x_i along the normal to axis i+1.
    frames: list[FloatArray] = []
    foot_in = points[0]  # where the previous normal meets axis i
    x_prev = _any_perpendicular(axes[0])
    for i in range(n):
        if i + 1 < n:
            foot1, foot2, x = _common_normal(foot_in, axes[i], points[i + 1], axes[i + 1],
                                             x_prev)
        else:
            foot1, foot2 = foot_in, foot_in
            x = x_prev - np.dot(x_prev, axes[i]) * axes[i]
            x = x / np.linalg.norm(x)
        frames.append(_frame(foot1, axes[i], x))
        foot_in, x_prev = foot2, x
    rows = np.zeros((n, 4))  # alpha, a, theta, d
    for i in range(1, n):
        rel = np.linalg.solve(frames[i - 1], frames[i])
        R, p = rel[:3, :3], rel[:3, 3]
        alpha = math.atan2(-R[1, 2], R[2, 2])
        rows[i] = (alpha, p[0], math.atan2(-R[0, 1], R[0, 0]),
                   float(np.dot(p, [0.0, -math.sin(alpha), math.cos(alpha)])))
    mass, com = _mass_model(robot, link_owner, link_pose, frames, n)
    index = {j.name: k for k, j in enumerate(movable)}
    coupled = [(index[j.name], index[j.mimic], j.multiplier, j.offset)
               for j in movable if j.mimic is not None]
    return chain_from_table(
        f"{robot.name}:{base_link}->{tip_link}", "mdh",
        a=rows[:, 1], alpha=rows[:, 0], d=rows[:, 3], theta=rows[:, 2],
        q_min=[j.lower for j in movable], q_max=[j.upper for j in movable],
        mass=mass, com=com, joint_types=[_MOVABLE[j.type] for j in movable],
        T_base_link0=frames[0], T_link_flange=np.linalg.solve(frames[-1], T_base_tip),
        coupled=coupled,
    )


def _attach_fixed_links(robot: UrdfRobot, link_owner: dict[str, int],
                        link_pose: dict[str, FloatArray]) -> None:
    """Add the links fixed (by chains of fixed joints) to a moving body off the path, such
    as a camera on the wrist or a tool past tip_link, to that body (in place, at q = 0)."""
    fixed = [j for j in robot.joints.values() if j.type == "fixed"]
    added = True
    while added:
        added = False
        for joint in fixed:
            if joint.parent in link_owner and joint.child not in link_owner:
                link_owner[joint.child] = link_owner[joint.parent]
                link_pose[joint.child] = link_pose[joint.parent] @ joint.origin
                added = True


def _mass_model(robot: UrdfRobot, link_owner: dict[str, int],
                link_pose: dict[str, FloatArray], frames: list[FloatArray], n: int
                ) -> tuple[FloatArray | None, FloatArray | None]:
    """Mass and centre of mass (in MDH frame j) of each moving body, or (None, None)."""
    if not any(link in robot.inertials for link in link_owner):
        return None, None
    mass = np.zeros(n)
    moment = np.zeros((n, 3))
    for link, j in link_owner.items():
        if link not in robot.inertials:
            continue
        m, c = robot.inertials[link]
        mass[j] += m
        moment[j] += m * (link_pose[link][:3, :3] @ c + link_pose[link][:3, 3])
    com = np.zeros((n, 3))
    for j in range(n):
        if mass[j] > 0:
            c_base = moment[j] / mass[j]
            com[j] = np.linalg.solve(frames[j], np.append(c_base, 1.0))[:3]
    return mass, com


def chain_joints(path: str | os.PathLike[str], base_link: str, tip_link: str
                 ) -> tuple[UrdfJoint, ...]:
    """The movable joints of the chain ``base_link`` .. ``tip_link`` of a URDF file, in the
    order of the chain's joint vector (q1 first): their URDF names and links for messages."""
    source = os.fspath(path)
    robot = parse_urdf(read_input_text(path, URDF, source), source)
    return tuple(j for j in _path(robot, base_link, tip_link, source) if j.type in _MOVABLE)


def load_urdf_chain(path: str | os.PathLike[str], base_link: str, tip_link: str) -> Chain:
    """Read a URDF file and return its chain from ``base_link`` to ``tip_link``.

    Raises:
        InputError: unreadable file, malformed URDF, unknown or unconnected links.
    """
    source = os.fspath(path)
    text = read_input_text(path, URDF, source)  # a regular file within the URDF size limit
    return chain_from_urdf(parse_urdf(text, source), base_link, tip_link, source)
