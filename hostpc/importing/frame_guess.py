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

Both are starting values that the fit refines, so they need not read every sample: an import
of a million rows reads an evenly strided :data:`GUESS_MAX_SAMPLES` of them (per marker), and
the hand-eye step compares at most two pose pairs per pose (:func:`hand_eye_pairs`), never
all N^2/2 of them, so time and memory stay bounded however long the file.

Shapes: ``T_base_flange`` ``(N, 4, 4)``; measured poses ``(N, 4, 4)``; points ``(N, 3)``;
all in SI units.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from hostpc.dataset.kind_registry import csv_row_shape
from hostpc.errors import InputError
from hostpc.importing.imported import ImportedSamples
from hostpc.json_object import JsonObject
from hostpc.kinematics.chain import Chain

__all__ = ["GUESS_MAX_SAMPLES", "guess_sample_indices", "guess_world_point",
           "guess_world_pose", "guessed_frames", "hand_eye_pairs"]

FloatArray = NDArray[np.float64]
IndexArray = NDArray[np.intp]

#: the most samples the guess reads: 20,000 poses pin a starting value far below any
#: instrument's noise, and the fit that follows reads every sample
GUESS_MAX_SAMPLES = 20_000
_ALL_PAIRS_MAX = 400  # the hand-eye step compares every pose pair up to this many


def hand_eye_pairs(n_poses: int) -> tuple[IndexArray, IndexArray]:
    """Index arrays ``(j, k)`` of the pose pairs the hand-eye step compares: every pair
    while there are at most 400, else each pose with the next one and with the one half-way
    round (``2 n_poses`` pairs): linear in the poses, never N^2/2."""
    if n_poses * (n_poses - 1) // 2 <= _ALL_PAIRS_MAX:
        first, second = np.triu_indices(n_poses, 1)
        return first, second
    k = np.arange(n_poses)
    return np.concatenate([k, k]), np.concatenate([(k + 1) % n_poses,
                                                   (k + n_poses // 2) % n_poses])


def guess_sample_indices(n_samples: int, marker_index: NDArray[np.int64] | None = None,
                         limit: int = GUESS_MAX_SAMPLES) -> IndexArray:
    """Which samples the guess reads: all up to ``limit``, else an even stride through the
    file, per marker (so that every marker keeps its share, at least 4 samples)."""
    if n_samples <= limit:
        return np.arange(n_samples)
    if marker_index is None:
        return np.arange(0, n_samples, -(-n_samples // limit))
    groups = [np.flatnonzero(marker_index == m) for m in np.unique(marker_index)]
    share = max(limit // len(groups), 4)
    return np.sort(np.concatenate([g[::max(1, -(-len(g) // share))] for g in groups]))


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

    first, second = hand_eye_pairs(len(T_base_flange))
    A = np.linalg.inv(T_base_flange)[first] @ T_base_flange[second]
    B = np.linalg.inv(T_world_meas)[first] @ T_world_meas[second]
    alpha = matrix_to_rotvec(A[:, :3, :3])
    beta = matrix_to_rotvec(B[:, :3, :3])
    R_X = _project_rotation(alpha.T @ beta)
    lhs = (A[:, :3, :3] - np.eye(3)).reshape(-1, 3)
    rhs = (B[:, :3, 3] @ R_X.T - A[:, :3, 3]).reshape(-1)
    X = np.eye(4)
    X[:3, :3] = R_X
    X[:3, 3] = np.linalg.lstsq(lhs, rhs, rcond=None)[0]
    return X


MIN_POSES = {"pose": 3, "point": 4}
"""The fewest measurements that place the world frame, per CSV row shape (full poses;
points)."""


def _too_few(method: str, needed: int) -> str:
    return f"{method}: at least {needed} poses are needed to place the world frame"


def guess_world_pose(T_base_flange: FloatArray, T_world_meas: FloatArray,
                     iterations: int = 20) -> tuple[FloatArray, FloatArray]:
    """``(T_world_base, T_flange_meas)`` that best explain full-pose measurements: the
    hand-eye solution for ``X``, then alternating rigid averages (module docstring)."""
    if len(T_base_flange) < MIN_POSES["pose"]:
        raise InputError(_too_few("world_pose", MIN_POSES["pose"]))
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
    if N < MIN_POSES["point"]:
        raise InputError(_too_few("world_point", MIN_POSES["point"]))
    index = np.zeros(N, dtype=np.int64) if marker_index is None else np.asarray(marker_index)
    M = int(index.max()) + 1
    markers = np.zeros((M, 3))
    R_base_flange, t_base_flange = T_base_flange[:, :3, :3], T_base_flange[:, :3, 3]
    W = np.eye(4)
    for _ in range(iterations):
        in_base = np.einsum("nij,nj->ni", R_base_flange, markers[index]) + t_base_flange
        W = _kabsch(in_base, points_world)
        # p_k = R_w (R_base_flange m + t_base_flange) + t_w
        #   ->  (R_w R_base_flange) m = p_k - t_w - R_w t_base_flange
        A = W[:3, :3] @ R_base_flange  # (N, 3, 3)
        b = points_world - W[:3, 3] - t_base_flange @ W[:3, :3].T
        new = np.zeros_like(markers)
        for m in range(M):
            rows = index == m
            new[m] = np.linalg.lstsq(A[rows].reshape(-1, 3), b[rows].reshape(-1),
                                     rcond=None)[0]
        if np.allclose(new, markers, atol=1e-12):
            break
        markers = new
    return _refine_world_point(W, markers, R_base_flange, t_base_flange, points_world, index)


def _refine_world_point(W: FloatArray, markers: FloatArray, R_base_flange: FloatArray,
                        t_base_flange: FloatArray, points: FloatArray, index: NDArray[np.int64]
                        ) -> tuple[FloatArray, FloatArray]:
    """Gauss-Newton on ``(rotation of W, t_W, markers)`` from the alternating estimate
    (which converges only linearly): ``p_k = R_W x_k + t_W`` with ``x_k = F_k m``."""
    from hostpc.kinematics.rotations import rotvec_to_matrix, skew

    N, M = len(points), len(markers)
    for _ in range(20):
        x = np.einsum("nij,nj->ni", R_base_flange, markers[index]) + t_base_flange
        Rx = x @ W[:3, :3].T
        r = (Rx + W[:3, 3] - points).reshape(-1)
        J = np.zeros((N, 3, 6 + 3 * M))
        J[:, :, :3] = -skew(Rx)
        J[:, :, 3:6] = np.eye(3)
        dx_dm = W[:3, :3] @ R_base_flange  # (N, 3, 3): each row's block at its marker's columns
        for axis in range(3):
            J[np.arange(N), :, 6 + 3 * index + axis] = dx_dm[:, :, axis]
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


def guessed_frames(samples: ImportedSamples, chain: Chain, frames: JsonObject) -> JsonObject:
    """``frames`` (the ``frames`` object of the document ``hostpc import`` writes, SI)
    with ``world`` and ``tool`` (world_pose) or ``markers`` (world_point, every name of
    ``frames["markers"]``) set to the estimates above, from at most
    :data:`GUESS_MAX_SAMPLES` of ``samples``."""
    from hostpc.kinematics import forward
    from hostpc.kinematics.rotations import pose_to_transform

    world_pose = csv_row_shape(samples.method) == "pose"
    needed = MIN_POSES["pose" if world_pose else "point"]
    if len(samples) < needed:
        raise InputError(
            f"{samples.source}: {len(samples)} measurement{'s' if len(samples) != 1 else ''}; "
            f"{_too_few(samples.method, needed)} (and a fit of the joint offsets "
            "needs many more, spread over the joints' ranges: docs/metrology.md); measure "
            "more poses and import the file again")
    pick = guess_sample_indices(len(samples), None if world_pose else samples.marker_index)
    T_base_flange = forward(chain, np.ascontiguousarray(samples.q[pick])).T_base_flange
    points = np.ascontiguousarray(samples.p[pick])
    guessed = dict(frames)
    if world_pose:
        assert samples.rpy is not None  # a world_pose import always has orientations
        W, X = guess_world_pose(T_base_flange, pose_to_transform(points, samples.rpy[pick]))
        guessed["tool"] = _pose_json(X)
    else:
        names = list(frames["markers"])
        index = (np.zeros(len(pick), dtype=np.int64) if samples.marker_index is None
                 else samples.marker_index[pick])
        W, markers = guess_world_point(T_base_flange, points, index)
        guessed["markers"] = {n: [float(v) for v in m] for n, m in zip(names, markers,
                                                                       strict=True)}
    guessed["world"] = _pose_json(W)
    return guessed
