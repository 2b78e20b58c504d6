"""Starting values of the unknown frames of world_pose and world_point data.

An external instrument's frame is usually far from the robot base (metres away, turned by
any angle), so the nominal frames the fit starts from must be estimated first; the fit then
only refines them. Both estimates alternate two closed-form steps until they settle:

- world_pose (``T_world_meas_k = W @ F_k @ X`` with ``F_k = T_base_flange(q_k)``): ``X``
  starts from the hand-eye solution of ``A X = X B`` over pose pairs; given ``X``, ``W``
  is the rigid average of ``T_world_meas_k @ inv(F_k @ X)``; given ``W``, ``X`` is the average of
  ``inv(W @ F_k) @ T_world_meas_k``. Rotation averages are the SVD projection of the mean.
- world_point (``p_k = W @ F_k @ m``): given the marker ``m``, ``W`` is the
  Kabsch fit of the points ``F_k m`` to ``p_k``; given ``W``, ``m`` is linear least squares.

Shapes: ``T_base_flange`` ``(N, 4, 4)``; measured poses ``(N, 4, 4)``; points ``(N, 3)``;
all in SI units.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from hostpc.errors import InputError
from hostpc.kinematics.chain import Chain

__all__ = ["guess_world_point", "guess_world_pose", "with_guessed_frames"]

FloatArray = NDArray[np.float64]


def _project_rotation(M: FloatArray) -> FloatArray:
    U, _, Vt = np.linalg.svd(M)
    D = np.diag([1.0, 1.0, float(np.sign(np.linalg.det(U @ Vt)))])
    rotation: FloatArray = U @ D @ Vt
    return rotation


def _rigid_mean(T: FloatArray) -> FloatArray:
    out = np.eye(4)
    out[:3, :3] = _project_rotation(T[:, :3, :3].mean(axis=0))
    out[:3, 3] = T[:, :3, 3].mean(axis=0)
    return out


def _hand_eye(T_base_flange: FloatArray, T_world_meas: FloatArray) -> FloatArray:
    """``X`` from ``A X = X B`` over pose pairs (Park and Martin): ``A = F_j^-1 F_k``,
    ``B = M_j^-1 M_k``; the rotation maps the axes of ``B`` onto those of ``A`` (Kabsch),
    the translation solves ``(R_A - I) t_X = R_X t_B - t_A`` in least squares."""
    from hostpc.kinematics.rotations import matrix_to_rotvec

    N = len(T_base_flange)
    pairs = [(j, k) for j in range(N) for k in range(j + 1, N)]
    if len(pairs) > 400:
        pairs = [(k, (k + step) % N) for step in (1, N // 2) for k in range(N)]
    F_inv = np.linalg.inv(T_base_flange)
    M_inv = np.linalg.inv(T_world_meas)
    A = np.array([F_inv[j] @ T_base_flange[k] for j, k in pairs])
    B = np.array([M_inv[j] @ T_world_meas[k] for j, k in pairs])
    alpha = np.array([matrix_to_rotvec(a[:3, :3]) for a in A])
    beta = np.array([matrix_to_rotvec(b[:3, :3]) for b in B])
    R_X = _project_rotation(alpha.T @ beta)
    lhs = (A[:, :3, :3] - np.eye(3)).reshape(-1, 3)
    rhs = (B[:, :3, 3] @ R_X.T - A[:, :3, 3]).reshape(-1)
    X = np.eye(4)
    X[:3, :3] = R_X
    X[:3, 3] = np.linalg.lstsq(lhs, rhs, rcond=None)[0]
    return X


def guess_world_pose(T_base_flange: FloatArray, T_world_meas: FloatArray,
                     iterations: int = 20) -> tuple[FloatArray, FloatArray]:
    """``(T_world_base, T_flange_meas)`` that best explain full-pose measurements: the
    hand-eye solution for ``X``, then alternating rigid averages (module docstring)."""
    if len(T_base_flange) < 3:
        raise InputError("world_pose: at least 3 poses are needed to place the world frame")
    X = _hand_eye(T_base_flange, T_world_meas)
    W = np.eye(4)
    for _ in range(iterations):
        W = _rigid_mean(T_world_meas @ np.linalg.inv(T_base_flange @ X))
        X_new = _rigid_mean(np.linalg.inv(W @ T_base_flange) @ T_world_meas)
        if np.allclose(X_new, X, atol=1e-13):
            break
        X = X_new
    return W, X


def _kabsch(source: FloatArray, target: FloatArray) -> FloatArray:
    """Rigid ``T`` minimising ``sum |T source_k - target_k|^2``."""
    cs, ct = source.mean(axis=0), target.mean(axis=0)
    H = (source - cs).T @ (target - ct)
    R = _project_rotation(H.T)
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = ct - R @ cs
    return T


def guess_world_point(T_base_flange: FloatArray, points_world: FloatArray,
                      marker_index: NDArray[np.int64] | None = None, iterations: int = 50
                      ) -> tuple[FloatArray, FloatArray]:
    """``(T_world_base, markers (M, 3) in the flange)`` that best explain measured points.

    ``marker_index`` (N,) says which marker each point is (default: all marker 0)."""
    N = len(T_base_flange)
    if N < 4:
        raise InputError("world_point: at least 4 poses are needed to place the world frame")
    index = np.zeros(N, dtype=np.int64) if marker_index is None else np.asarray(marker_index)
    M = int(index.max()) + 1
    markers = np.zeros((M, 3))
    R_bf, t_bf = T_base_flange[:, :3, :3], T_base_flange[:, :3, 3]
    W = np.eye(4)
    for _ in range(iterations):
        in_base = np.einsum("nij,nj->ni", R_bf, markers[index]) + t_bf
        W = _kabsch(in_base, points_world)
        # p_k = R_w (R_bf m + t_bf) + t_w  ->  (R_w R_bf) m = p_k - t_w - R_w t_bf
        A = W[:3, :3] @ R_bf  # (N, 3, 3)
        b = points_world - W[:3, 3] - t_bf @ W[:3, :3].T
        new = np.zeros_like(markers)
        for m in range(M):
            rows = index == m
            new[m] = np.linalg.lstsq(A[rows].reshape(-1, 3), b[rows].reshape(-1),
                                     rcond=None)[0]
        if np.allclose(new, markers, atol=1e-12):
            break
        markers = new
    return _refine_world_point(W, markers, R_bf, t_bf, points_world, index)


def _refine_world_point(W: FloatArray, markers: FloatArray, R_bf: FloatArray,
                        t_bf: FloatArray, points: FloatArray, index: NDArray[np.int64]
                        ) -> tuple[FloatArray, FloatArray]:
    """Gauss-Newton on ``(rotation of W, t_W, markers)`` from the alternating estimate
    (which converges only linearly): ``p_k = R_W x_k + t_W`` with ``x_k = F_k m``."""
    from hostpc.kinematics.rotations import rotvec_to_matrix, skew

    N, M = len(points), len(markers)
    for _ in range(20):
        x = np.einsum("nij,nj->ni", R_bf, markers[index]) + t_bf
        Rx = x @ W[:3, :3].T
        r = (Rx + W[:3, 3] - points).reshape(-1)
        J = np.zeros((N, 3, 6 + 3 * M))
        J[:, :, :3] = -np.array([skew(v) for v in Rx])
        J[:, :, 3:6] = np.eye(3)
        for k in range(N):
            J[k, :, 6 + 3 * index[k]:9 + 3 * index[k]] = W[:3, :3] @ R_bf[k]
        step = np.linalg.lstsq(J.reshape(-1, 6 + 3 * M), -r, rcond=None)[0]
        W = W.copy()
        W[:3, :3] = rotvec_to_matrix(step[:3]) @ W[:3, :3]
        W[:3, 3] += step[3:6]
        markers = markers + step[6:].reshape(M, 3)
        if np.max(np.abs(step)) < 1e-14:
            break
    return W, markers


def _pose_json(T: FloatArray) -> dict[str, list[float]]:
    from hostpc.kinematics.rotations import matrix_to_rpy

    return {"xyz": [float(v) for v in T[:3, 3]],
            "rpy": [float(v) for v in matrix_to_rpy(T[:3, :3])]}


def with_guessed_frames(document: dict[str, Any], chain: Chain) -> dict[str, Any]:
    """A copy of an imported world_point / world_pose document whose nominal ``world``
    and ``tool`` (or ``markers``) frames are the estimates above (SI document)."""
    from hostpc.kinematics import forward
    from hostpc.kinematics.rotations import pose_to_transform

    samples = document["samples"]
    q = np.array([s["q"] for s in samples], dtype=np.float64)
    T_base_flange = forward(chain, q).T_base_flange
    points = np.array([s["p"] for s in samples], dtype=np.float64)
    frames = dict(document["frames"])
    if document["method"] == "world_pose":
        T_meas = np.array([pose_to_transform(p, np.asarray(s["rpy"], float))
                           for p, s in zip(points, samples, strict=True)])
        W, X = guess_world_pose(T_base_flange, T_meas)
        frames["tool"] = _pose_json(X)
    else:
        names = list(frames["markers"])
        index = np.array([names.index(s.get("marker", names[0])) for s in samples])
        W, markers = guess_world_point(T_base_flange, points, index)
        frames["markers"] = {n: [float(v) for v in m] for n, m in zip(names, markers,
                                                                      strict=True)}
    frames["world"] = _pose_json(W)
    return {**document, "frames": frames}
