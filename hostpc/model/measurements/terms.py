"""The pieces every measurement model composes: joint and geometry effects as per-pose
kinematic deltas with their derivatives, frames with their deltas applied, fixed points seen
from the base, and the sensor effects applied last (chain rule through each).

Shapes: N samples, n joints, P parameters; a kinematic-delta vector per pose is ordered
theta, d, a, alpha, beta (5n, docs/conventions.md).
"""

from __future__ import annotations

import numpy as np

from hostpc.kinematics import Chain, forward
from hostpc.kinematics.jacobians import KinematicScrews, joint_screws, screws
from hostpc.kinematics.poses import ChainPoses
from hostpc.kinematics.rotations import pose_to_transform
from hostpc.model.effect import EffectTerm, numeric_jacobian
from hostpc.model.frame_math import inverse_point_derivatives, perturbed_pose
from hostpc.model.layout import Problem

__all__ = ["apply_sensor_effects", "flange", "frame_pose", "kinematic_deltas",
           "row_screws", "screw_rows", "world_point_in_base"]


def _term_params(term: EffectTerm | None, x: np.ndarray) -> np.ndarray | None:
    return None if term is None else x[term.slice]


def kinematic_deltas(problem: Problem, x: np.ndarray, jacobian: bool
                     ) -> tuple[np.ndarray, np.ndarray | None, slice]:
    """Per-pose kinematic deltas (N, 5n), their derivative by x (N, k, P) over the rows
    that effects touch, and that row slice (the theta rows only, unless a geometry effect).
    A coupled joint (``Chain.coupled``) follows its leader's joint-space corrections and
    has none of its own: its own parameters of every joint effect (offset, compliance,
    encoder scale, a plugin's) move nothing, and the fit holds them ("no effect")."""
    ctx = problem.context
    n_samples, n_joints = ctx.q_cmd.shape
    geometric = any(t.effect.hook == "geometry" for t in problem.terms)
    rows = slice(0, 5 * n_joints) if geometric else slice(0, n_joints)
    delta = np.zeros((n_samples, 5 * n_joints))
    d_delta = np.zeros((n_samples, rows.stop, x.size)) if jacobian else None
    # the joint effects' part, (N, n) and (N, n, P): what a coupled joint follows; without
    # coupled joints, views of the theta rows (added there directly, no copy)
    coupled = ctx.chain.coupled
    joint = np.zeros((n_samples, n_joints)) if coupled else delta[:, :n_joints]
    d_joint = (None if d_delta is None else
               np.zeros((n_samples, n_joints, x.size)) if coupled else d_delta[:, :n_joints])
    for term, basis in zip(problem.terms, problem.linear_bases or (None,) * len(problem.terms),
                           strict=False):
        hook = term.effect.hook
        if hook not in ("joint", "geometry"):
            continue
        p = x[term.slice]
        value, derivative = ((joint, d_joint) if hook == "joint" else
                             (delta, d_delta))
        if basis is not None:
            value[:, :basis.shape[1]] += basis @ p
            if derivative is not None:
                derivative[:, :basis.shape[1], term.slice] += basis
            continue
        fun, jac = ((term.effect.joint_delta, term.effect.joint_jacobian) if hook == "joint"
                    else (term.effect.kinematic_delta, term.effect.kinematic_jacobian))
        value += fun(ctx, p)
        if derivative is not None:
            J = jac(ctx, p)
            if J is None:
                J = numeric_jacobian(lambda v, f=fun: f(ctx, v), p)
            derivative[:, :, term.slice] += J
    if coupled:  # a follower moves only with its leader: no joint-space change of its own
        for follower, leader, multiplier, _ in coupled:
            joint[:, follower] = multiplier * joint[:, leader]
            if d_joint is not None:
                d_joint[:, follower] = multiplier * d_joint[:, leader]
        delta[:, :n_joints] += joint
        if d_delta is not None and d_joint is not None:
            d_delta[:, :n_joints] += d_joint
    return delta, d_delta, rows


def screw_rows(screws: KinematicScrews, rows: slice) -> KinematicScrews:
    """The screws of the kinematic-delta rows ``rows`` only (see kinematic_deltas), so that
    a point Jacobian is computed for the n theta rows of an offsets fit, not all 5n."""
    return KinematicScrews(axis=screws.axis[:, rows], point=screws.point[:, rows],
                           is_rotation=screws.is_rotation[rows])


def row_screws(chain: Chain, poses: ChainPoses, rows: slice) -> KinematicScrews:
    """The screws of the kinematic-delta rows ``rows`` (see kinematic_deltas): for the theta
    rows of a fit without a geometry effect only those n are computed, not all 5n."""
    if rows.start in (0, None) and rows.stop == chain.n and rows.step in (1, None):
        return joint_screws(chain, poses)
    return screw_rows(screws(chain, poses), rows)


def frame_pose(problem: Problem, name: str, x: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(R, t, J_r) of a pose frame (tool or base) with its delta applied, if estimated."""
    if name not in problem.dataset.frames:
        T = np.eye(4)
    else:
        frame = problem.dataset.pose(name)
        T = pose_to_transform(np.asarray(frame.xyz, float), np.asarray(frame.rpy, float))
    term = problem.term(name)
    delta = _term_params(term, x)
    if delta is not None and delta.size == 3:  # point-only tool (sphere_probe)
        delta = np.concatenate([delta, np.zeros(3)])
    return perturbed_pose(T[:3, :3], T[:3, 3], delta)


def world_point_in_base(problem: Problem, x: np.ndarray, point_name: str, nominal: np.ndarray
                         ) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """A fixed world point (target or sphere centre) in base coordinates (3,), and its
    derivatives (3, P_term) by the point's own term and the base term."""
    term = problem.term(point_name)
    point_world = nominal + (x[term.slice] if term is not None else 0.0)
    derivatives: dict[str, np.ndarray] = {}
    base_term = problem.term("base")
    if base_term is None:
        if term is not None:
            derivatives[point_name] = np.eye(3)
        return point_world, derivatives
    R_world_base, t_world_base, J_r = frame_pose(problem, "base", x)
    point_base = R_world_base.T @ (point_world - t_world_base)
    dy_dt, dy_dr = inverse_point_derivatives(point_base[None, :], R_world_base, J_r)
    derivatives["base"] = np.concatenate([dy_dt, dy_dr[0]], axis=1)
    if term is not None:
        derivatives[point_name] = R_world_base.T
    return point_base, derivatives


def flange(problem: Problem, x: np.ndarray, jacobian: bool
           ) -> tuple[ChainPoses, np.ndarray, np.ndarray, np.ndarray | None, slice]:
    """Forward kinematics with the joint and geometry effects applied: the chain poses,
    R_base_flange (N, 3, 3), t_base_flange (N, 3), and the kinematic-delta derivative with its
    row slice (see kinematic_deltas)."""
    delta, d_delta, rows = kinematic_deltas(problem, x, jacobian)
    n_joints = problem.context.q_cmd.shape[1]
    if rows.stop == n_joints:  # joint deltas only: the joint variables move, the table not
        poses = forward(problem.chain, problem.context.q_cmd + delta[:, :n_joints])
    else:
        poses = forward(problem.chain, problem.context.q_cmd, delta)
    T_base_flange = poses.T_base_flange
    return poses, T_base_flange[:, :3, :3], T_base_flange[:, :3, 3], d_delta, rows


def apply_sensor_effects(problem: Problem, x: np.ndarray, y: np.ndarray, J: np.ndarray | None
                         ) -> tuple[np.ndarray, np.ndarray | None]:
    """Apply the sensor effects in order to the ideal measurement y (N, m), carrying its
    Jacobian J (N, m, P) through them by the chain rule (J None: values only)."""
    for term in problem.terms:
        if term.effect.hook != "sensor":
            continue
        p = x[term.slice]
        if J is not None:
            analytic = term.effect.sensor_jacobians(problem.context, p, y)
            if analytic is None:
                d_out_d_p, d_out_d_y = _numeric_sensor_jacobians(term, problem, p, y)
            else:
                d_out_d_y, d_out_d_p = analytic
            J = np.einsum("nij,njp->nip", d_out_d_y, J)
            J[:, :, term.slice] += d_out_d_p
        y = term.effect.sensor_apply(problem.context, p, y)
    return y, J


def _numeric_sensor_jacobians(term: EffectTerm, problem: Problem, p: np.ndarray, y: np.ndarray
                              ) -> tuple[np.ndarray, np.ndarray]:
    """Central differences of a sensor effect without analytic Jacobians: (N,3,P), (N,3,3).
    A sensor function acts on each sample's point independently."""
    def apply(pp: np.ndarray, yy: np.ndarray) -> np.ndarray:
        return np.asarray(term.effect.sensor_apply(problem.context, pp, yy), dtype=float)

    d_out_d_p = numeric_jacobian(lambda v: apply(v, y), p)
    m = y.shape[1]
    d_out_d_y = np.zeros((y.shape[0], m, m))
    for k in range(m):
        h = 1e-7 * max(1.0, float(np.max(np.abs(y[:, k]))))
        step = np.zeros(m)
        step[k] = h
        d_out_d_y[:, :, k] = (apply(p, y + step) - apply(p, y - step)) / (2.0 * h)
    return d_out_d_p, d_out_d_y


