"""Measurement models: predicted measurements and their analytic Jacobians.

``predict(problem, x, jacobian=True)`` returns the predicted measurement (N, m) and its
derivative by the parameter vector (N, m, P). The Jacobian is composed by the chain rule:
joint and geometry effects give per-pose kinematic deltas (N, 5n) and their derivatives
(N, 5n, P_effect); the kinematic screws give d(flange motion)/d(kinematic parameter); frame
and sensor effects add their own factors. Effects without analytic Jacobians are
differentiated numerically here.

- stereo_target (m = 3): the target point in the sensor frame,
  ``y = R_ft^T (R_bf^T (p_b - t_bf) - t_ft)``, then sensor effects in order.
- sphere_probe (m = 1): the distance from the stylus tip centre to the sphere centre,
  ``|R_bf t_ft + t_bf - c_b|``.
"""

from __future__ import annotations

import numpy as np

from hostpc.kinematics import forward, point_jacobian, screws
from hostpc.kinematics.rotations import pose_to_transform
from hostpc.model.dual_loop import predict_dual_loop
from hostpc.model.effect import EffectTerm, numeric_jacobian
from hostpc.model.frame_math import inverse_point_derivatives, perturbed_pose
from hostpc.model.problem import Problem


def _term_params(term: EffectTerm | None, x: np.ndarray) -> np.ndarray | None:
    return None if term is None else x[term.slice]


def kinematic_deltas(problem: Problem, x: np.ndarray, jacobian: bool
                     ) -> tuple[np.ndarray, np.ndarray | None, slice]:
    """Per-pose kinematic deltas (N, 5n), their derivative by x (N, k, P) over the rows
    that effects touch, and that row slice (the theta rows only, unless a geometry effect)."""
    ctx = problem.context
    n_samples, n_joints = ctx.q_cmd.shape
    geometric = any(t.effect.hook == "geometry" for t in problem.terms)
    rows = slice(0, 5 * n_joints) if geometric else slice(0, n_joints)
    delta = np.zeros((n_samples, 5 * n_joints))
    d_delta = np.zeros((n_samples, rows.stop, x.size)) if jacobian else None
    for term, basis in zip(problem.terms, problem.linear_bases or (None,) * len(problem.terms),
                           strict=False):
        hook = term.effect.hook
        if hook not in ("joint", "geometry"):
            continue
        p = x[term.slice]
        target = slice(0, n_joints) if hook == "joint" else slice(0, 5 * n_joints)
        if basis is not None:
            delta[:, target] += basis @ p
            if d_delta is not None:
                d_delta[:, target, term.slice] += basis
            continue
        if hook == "joint":
            delta[:, target] += term.effect.joint_delta(ctx, p)
            J = term.effect.joint_jacobian(ctx, p) if d_delta is not None else None
            if d_delta is not None and J is None:
                J = numeric_jacobian(lambda v, e=term.effect: e.joint_delta(ctx, v), p)
        else:
            delta[:, target] += term.effect.kinematic_delta(ctx, p)
            J = term.effect.kinematic_jacobian(ctx, p) if d_delta is not None else None
            if d_delta is not None and J is None:
                J = numeric_jacobian(lambda v, e=term.effect: e.kinematic_delta(ctx, v), p)
        if d_delta is not None:
            d_delta[:, target, term.slice] += J
    return delta, d_delta, rows


def _frame_pose(problem: Problem, name: str, x: np.ndarray):  # type: ignore[no-untyped-def]
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


def _world_point_in_base(problem: Problem, x: np.ndarray, point_name: str, nominal: np.ndarray
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
    R_wb, t_wb, J_r = _frame_pose(problem, "base", x)
    point_base = R_wb.T @ (point_world - t_wb)
    dy_dt, dy_dr = inverse_point_derivatives(point_base[None, :], R_wb, J_r)
    derivatives["base"] = np.concatenate([dy_dt, dy_dr[0]], axis=1)
    if term is not None:
        derivatives[point_name] = R_wb.T
    return point_base, derivatives


def _flange(problem: Problem, x: np.ndarray, jacobian: bool):  # type: ignore[no-untyped-def]
    """Forward kinematics with the joint and geometry effects applied: the chain poses,
    R_base_flange (N, 3, 3), t_base_flange (N, 3), and the kinematic-delta derivative with its
    row slice (see kinematic_deltas)."""
    delta, d_delta, rows = kinematic_deltas(problem, x, jacobian)
    poses = forward(problem.chain, problem.context.q_cmd, delta)
    T_bf = poses.T_base_flange
    return poses, T_bf[:, :3, :3], T_bf[:, :3, 3], d_delta, rows


def predict_stereo_target(problem: Problem, x: np.ndarray, jacobian: bool = True
                          ) -> tuple[np.ndarray, np.ndarray | None]:
    """Predicted target point in the sensor frame (N, 3) and d/dx (N, 3, P)."""
    chain = problem.chain
    poses, R_bf, t_bf, d_delta, rows = _flange(problem, x, jacobian)
    p_b, d_pb = _world_point_in_base(
        problem, x, "target", np.asarray(problem.dataset.frames["target"], dtype=float)
    )
    R_ft, t_ft, J_r_tool = _frame_pose(problem, "tool", x)
    R_bf_T = np.swapaxes(R_bf, 1, 2)
    p_f = np.einsum("nij,nj->ni", R_bf_T, p_b[None, :] - t_bf)
    y = (p_f - t_ft) @ R_ft  # rows: R_ft^T (p_f - t_ft)
    if not jacobian:
        return apply_sensor_effects(problem, x, y, None)
    assert d_delta is not None
    n_samples = y.shape[0]
    J = np.zeros((n_samples, 3, x.size))
    # kinematic parameters: moving the flange by a screw moves the fixed target point the
    # opposite way in the flange frame: dp_f = -R_bf^T (w x (p_b - c)) or -R_bf^T v
    S = screws(chain, poses)
    d_pb_world_dkin = point_jacobian(S, np.broadcast_to(p_b, (n_samples, 3)))[:, :, rows]
    A = R_ft.T @ R_bf_T  # (N, 3, 3): d y / d p_b  (and -d y / d (flange motion))
    J -= (A @ d_pb_world_dkin) @ d_delta
    for name, d_pb_term in d_pb.items():
        span = problem.term(name).slice  # type: ignore[union-attr]
        J[:, :, span] += A @ d_pb_term
    tool = problem.term("tool")
    if tool is not None:
        dy_dt, dy_dr = inverse_point_derivatives(y, R_ft, J_r_tool)
        J[:, :, tool.slice.start:tool.slice.start + 3] += dy_dt
        J[:, :, tool.slice.start + 3:tool.slice.stop] += dy_dr
    return apply_sensor_effects(problem, x, y, J)


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


def predict_sphere_probe(problem: Problem, x: np.ndarray, jacobian: bool = True
                         ) -> tuple[np.ndarray, np.ndarray | None]:
    """Predicted tip-to-centre distance (N, 1) and d/dx (N, 1, P)."""
    chain = problem.chain
    poses, R_bf, t_bf, d_delta, rows = _flange(problem, x, jacobian)
    _, t_ft, _ = _frame_pose(problem, "tool", x)
    tip = np.einsum("nij,j->ni", R_bf, t_ft) + t_bf
    sphere = problem.dataset.sphere()
    c_b, d_cb = _world_point_in_base(problem, x, "sphere", np.asarray(sphere.center, float))
    diff = tip - c_b[None, :]
    distance = np.linalg.norm(diff, axis=1)
    prediction = distance[:, None]
    if not jacobian:
        return apply_sensor_effects(problem, x, prediction, None)
    assert d_delta is not None
    u = diff / distance[:, None]
    n_samples = tip.shape[0]
    J = np.zeros((n_samples, 1, x.size))
    d_tip_dkin = point_jacobian(screws(chain, poses), tip)[:, :, rows]
    d_dist_dkin = (u[:, None, :] @ d_tip_dkin)  # (N, 1, k)
    J += d_dist_dkin @ d_delta
    tool = problem.term("tool")
    if tool is not None:
        J[:, 0, tool.slice] += np.einsum("ni,nij->nj", u, R_bf)
    for name, d_cb_term in d_cb.items():
        span = problem.term(name).slice  # type: ignore[union-attr]
        J[:, 0, span] -= u @ d_cb_term
    return apply_sensor_effects(problem, x, prediction, J)


PREDICTORS = {
    "stereo_target": predict_stereo_target,
    "sphere_probe": predict_sphere_probe,
    "dual_loop": predict_dual_loop,
}


def predict(problem: Problem, x: np.ndarray, jacobian: bool = True
            ) -> tuple[np.ndarray, np.ndarray | None]:
    """Predicted measurements (N, m) and their derivative by x (N, m, P) (or None)."""
    return PREDICTORS[problem.method](problem, np.asarray(x, dtype=float), jacobian)
