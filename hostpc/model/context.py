"""What a model may read about a serial robot's samples: its chain and its ModelContext.

The default of every measurement model on a serial robot (a tree, such as dual_loop's,
builds its own); computed once per problem, including the gravity torques.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence

import numpy as np

from hostpc.dataset import Dataset, Samples
from hostpc.errors import InputError
from hostpc.kinematics import Chain, gravity_torque
from hostpc.kinematics.robots import get_robot
from hostpc.kinematics.tables import chain_from_table
from hostpc.model.effect import ModelContext


def chain_version(dataset: Dataset) -> tuple[int, int] | None:
    """What a chain built from the dataset's robot description depends on beyond it: the
    URDF file's version (modification time, size), (0, 0) without a URDF; None if the file
    cannot be read (then nothing may be kept: the loader says what is wrong)."""
    if dataset.robot.urdf is None:
        return (0, 0)
    try:
        stat = os.stat(dataset.robot.urdf)
    except OSError:
        return None
    return (stat.st_mtime_ns, stat.st_size)


def serial_chain(dataset: Dataset) -> Chain:
    """The nominal chain of the dataset's robot (built-in by name, explicit table or URDF)."""
    robot = dataset.robot
    if robot.name is not None and robot.a is None:
        return get_robot(robot.name)
    if robot.urdf is not None:  # extension A: a URDF chain (hostpc.kinematics.urdf)
        from hostpc.kinematics.urdf import load_urdf_chain

        assert robot.base_link is not None and robot.tip_link is not None
        return load_urdf_chain(robot.urdf, robot.base_link, robot.tip_link)
    # the dataset layer guarantees a complete explicit table when there is no name
    assert robot.convention is not None and robot.a is not None and robot.alpha is not None
    assert robot.d is not None and robot.theta is not None
    return chain_from_table(
        robot.name or "explicit",
        robot.convention,
        robot.a,
        robot.alpha,
        robot.d,
        robot.theta,
        mass=robot.mass,
        com=robot.com,
        joint_types=robot.joint_types,
    )


FINGERPRINT_DIGITS = 9
"""Significant digits of each table entry in a robot's fingerprint: a JSON round trip or a
mm/deg file of the same robot gives the same fingerprint, a changed dimension another."""


def chain_fingerprint(chains: Sequence[Chain]) -> str:
    """A short hash of the nominal kinematics of ``chains`` (convention, every table entry,
    joint types, mounts, coupled joints): two robots with the same fingerprint move alike."""
    import hashlib

    parts: list[str] = []
    for chain in chains:
        assert chain.T_base_link0 is not None and chain.T_link_flange is not None
        numbers = np.concatenate([chain.a, chain.alpha, chain.d, chain.theta, chain.beta,
                                  chain.T_base_link0[:3].ravel(), chain.T_link_flange[:3].ravel()])
        parts.append(chain.convention + ":" + "".join("P" if p else "R"
                                                      for p in chain.joint_is_prismatic))
        parts.append(",".join(f"{v + 0.0:.{FINGERPRINT_DIGITS}g}" for v in numbers))
        parts.append(",".join(f"{f}<{leader}:{m:.{FINGERPRINT_DIGITS}g}:{c:.{FINGERPRINT_DIGITS}g}"
                              for f, leader, m, c in chain.coupled))
    return hashlib.sha256(";".join(parts).encode()).hexdigest()[:16]


def robot_identity(dataset: Dataset) -> dict[str, str]:
    """What a fit records of its robot, so that a fit is never applied to another robot:
    ``name`` (a built-in's, the URDF chain's ``robot:base->tip``, or ``explicit table``)
    and ``kinematics``, the fingerprint of its nominal chain(s) (:func:`chain_fingerprint`)."""
    from hostpc.kinematics.humanoid import get_tree, tree_names

    robot = dataset.robot
    if robot.name is not None and robot.a is None and robot.name in tree_names():
        chains = [branch.chain for branch in get_tree(robot.name).branches]
        return {"name": robot.name, "kinematics": chain_fingerprint(chains)}
    chain = serial_chain(dataset)
    name = robot.name or (chain.name if robot.urdf is not None else "explicit table")
    return {"name": name, "kinematics": chain_fingerprint([chain])}


COUPLED_TOLERANCE = 1e-6
"""How far (rad, or m for a prismatic joint) a coupled joint's recorded value may be from
``multiplier * q_leader + offset``: the rounding of a CSV, not a different motion."""


def check_coupled_joints(chain: Chain, q: np.ndarray,
                         urdf: tuple[str, str, str] | None = None) -> None:
    """Every sample's coupled joint (``Chain.coupled``, a URDF ``<mimic>``) at its leader's
    value times the multiplier plus the offset, as the robot reports it; InputError (one
    line) naming the joints (by their URDF names when ``urdf``, the chain's (URDF file,
    base link, tip link), is given), the first sample that is not and what to do (`hostpc
    import` and every fit check it)."""
    for follower, leader, multiplier, offset in chain.coupled:
        expected = multiplier * q[:, leader] + offset
        off = np.abs(q[:, follower] - expected) > COUPLED_TOLERANCE
        if not np.any(off):
            continue
        k = int(np.argmax(off))
        name_f, name_l = f"q{follower + 1}", f"q{leader + 1}"
        end = "or end the chain before it"
        if urdf is not None:
            from hostpc.kinematics.urdf import chain_joints  # xml.etree: only for a URDF

            path, base_link, _ = urdf
            joints = chain_joints(*urdf)
            name_f = f"{joints[follower].name} (q{follower + 1})"
            name_l = f"{joints[leader].name} (q{leader + 1})"
            end = (f"or end the chain before it: --robot {path} --base-link {base_link} "
                   f"--tip-link {joints[follower].parent}")
        raise InputError(
            f"joint {name_f} follows {name_l} (<mimic>: {multiplier:g} x leader + "
            f"{offset:g}), but sample #{k} has {q[k, follower]:.9g} instead of "
            f"{expected[k]:.9g}: record the joint as the robot reports it (ROS joint_states "
            "do; check which column --columns maps to it) and import again, " + end)


def sample_variables(samples: Samples, scalars: tuple[str, ...] = ("t", "temperature", "speed")
                     ) -> dict[str, np.ndarray]:
    """The per-sample variables every method shares, by contract name, each (N,): the
    recorded scalars that any sample has, `depth` (the measured point's z in the sensor
    frame, m) and `extra.NAME`."""
    variables: dict[str, np.ndarray] = {}
    for name in scalars:
        values = getattr(samples, name)
        if values is not None and np.any(np.isfinite(values)):
            variables[name] = np.asarray(values, dtype=float)
    if samples.p is not None:
        variables["depth"] = np.asarray(samples.p, dtype=float)[:, 2]
    for name, values in samples.extra.items():
        if np.any(np.isfinite(values)):
            variables[f"extra.{name}"] = np.asarray(values, dtype=float)
    return variables


def group_variable(labels: Sequence[object]) -> tuple[np.ndarray, tuple[str, ...]]:
    """A categorical variable from per-sample labels (N,): (level index of each sample as
    float (N,), NaN where the label is empty or None; the level names, in order of first
    appearance). What a measurement model puts in ``ModelContext.variables`` and
    ``ModelContext.categorical`` for a group of samples (a marker, an arm, a session)."""
    levels: list[str] = []
    codes = np.full(len(labels), np.nan)
    for i, label in enumerate(labels):
        if label is None or str(label) == "":
            continue
        name = str(label)
        if name not in levels:
            levels.append(name)
        codes[i] = levels.index(name)
    return codes, tuple(levels)


def serial_context(dataset: Dataset, chain: Chain,
                   frame_parameters: Mapping[str, tuple[str, ...]] | None = None,
                   variables: Mapping[str, np.ndarray] | None = None,
                   categorical: Mapping[str, tuple[str, ...]] | None = None) -> ModelContext:
    """The ModelContext of a serial robot's samples: q_cmd, gravity torques (NaN without
    mass data), approach signs and the contract variables (``q1``, ``tau1``,
    ``approach1``, ... and ``sample_variables``, or the given ``variables`` instead);
    ``categorical``: which of the given variables are group labels, with their levels."""
    samples = dataset.samples
    q_cmd = np.asarray(samples.q, dtype=float)
    robot = dataset.robot
    check_coupled_joints(chain, q_cmd, None if robot.urdf is None else
                         (robot.urdf, str(robot.base_link), str(robot.tip_link)))
    if chain.mass is not None and chain.com is not None:  # once per build: views share it
        tau = gravity_torque(chain, q_cmd)
        tau.setflags(write=False)  # shared by the problem's views and extensions
    else:
        tau = np.full_like(q_cmd, np.nan)
    approach = np.nan_to_num(np.asarray(samples.approach, dtype=float), nan=0.0)
    named: dict[str, np.ndarray] = {}
    for j in range(chain.n):
        named[f"q{j + 1}"] = q_cmd[:, j]
    if np.all(np.isfinite(tau)):
        for j in range(chain.n):
            named[f"tau{j + 1}"] = tau[:, j]
    if np.any(np.isfinite(samples.approach)):
        for j in range(chain.n):
            named[f"approach{j + 1}"] = approach[:, j]
    named.update(sample_variables(samples) if variables is None else variables)
    return ModelContext(
        chain=chain, method=dataset.method, q_cmd=q_cmd, tau=tau, approach=approach,
        variables=named, frame_parameters=dict(frame_parameters or {}),
        categorical=dict(categorical or {}),
    )
