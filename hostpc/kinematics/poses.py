"""Forward kinematics of a :class:`Chain` for N poses at once.

Per joint (``docs/conventions.md``), with effective row values
``theta_i + q_i + dtheta_i``, ``d_i + dd_i``, ``a_i + da_i``, ``alpha_i + dalpha_i``,
``beta_i + dbeta_i``:

- DH:  ``T_{i-1}_{i} = Rz(theta) @ Tz(d) @ Tx(a) @ Rx(alpha) @ Ry(beta)``
- MDH: ``T_{i-1}_{i} = Rx(alpha) @ Ry(beta) @ Tx(a) @ Rz(theta) @ Tz(d)``

Internally the frames are stored component-major, ``(n+1, 4, 4, N)``, so every operation
runs over contiguous length-N vectors; ``ChainPoses.T_base_link`` is a pose-major view of
that buffer. Each joint transform is split into the joint rotation ``Rz(theta)`` and a
fixed factor ``F`` (DH: ``Tz(d) Tx(a) Rx(alpha) Ry(beta)``; MDH: ``Rx(alpha) Ry(beta)
Tx(a)``); when ``F`` is the same for all poses (``kin_delta`` None, ``(5n,)``, or
``(N, 5n)`` differing between poses only in its theta rows) it is applied with one small
matrix product per joint. The only Python loop runs over the joints.

A prismatic joint (``chain.prismatic``) adds its joint variable ``q_i + dtheta_i`` (m) as a
translation ``Tz`` next to ``Tz(d)``, and its fixed rotation about the axis is
``theta_i + dd_i`` (the two slots swap roles, ``chain.py``). A chain with mounts starts at
``T_base_link0`` and its flange is ``T_base_link_n @ T_link_flange``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from hostpc.errors import InputError
from hostpc.kinematics.chain import Chain

__all__ = ["ChainPoses", "forward", "check_q", "check_kin_delta"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class ChainPoses:
    """Link frames of a chain at N poses, plus the row angles :func:`screws` needs.

    Attributes:
        convention: the chain's convention, ``"dh"`` or ``"mdh"``.
        T_base_link: ``T_base_link_i`` for ``i = 0..n``, shape ``(N, n+1, 4, 4)``;
            ``[:, 0]`` is the identity (base) and ``[:, n]`` the flange. From
            :func:`forward` this is a (non-contiguous) view of a component-major buffer.
        cos_theta, sin_theta: cos and sin of the effective ``theta_i + q_i + dtheta_i``,
            shape ``(N, n)``.
        cos_alpha, sin_alpha: of the effective ``alpha_i``, shape ``(N, n)`` (a broadcast
            view when the twist does not vary per pose).
        cos_beta, sin_beta: of the effective ``beta_i``, shape ``(N, n)`` (idem).
        T_link_flange: the chain's fixed flange mount, ``(4, 4)``, or None (identity).
    """

    convention: str
    T_base_link: FloatArray
    cos_theta: FloatArray
    sin_theta: FloatArray
    cos_alpha: FloatArray
    sin_alpha: FloatArray
    cos_beta: FloatArray
    sin_beta: FloatArray
    T_link_flange: FloatArray | None = None

    @property
    def n(self) -> int:
        """Number of joints."""
        return int(self.T_base_link.shape[1]) - 1

    @property
    def T_base_flange(self) -> FloatArray:
        """Flange poses in base, shape ``(N, 4, 4)``: the last link frame, times the
        flange mount when the chain has one."""
        if self.T_link_flange is None:
            return self.T_base_link[:, -1]
        flange: FloatArray = self.T_base_link[:, -1] @ self.T_link_flange
        return flange


def check_q(chain: Chain, q: ArrayLike, name: str = "q") -> FloatArray:
    """``q`` as a float array of shape ``(N, n)``; InputError naming ``name`` otherwise."""
    arr = np.asarray(q, dtype=np.float64)
    if arr.ndim != 2 or arr.shape[1] != chain.n:
        raise InputError(f"{name}: expected shape (N, {chain.n}), got {arr.shape}")
    return arr


def check_kin_delta(
    chain: Chain, kin_delta: ArrayLike | None, N: int, name: str = "kin_delta"
) -> FloatArray | None:
    """``kin_delta`` as ``(N, 5n)`` or ``(5n,)`` float array (or None); InputError else."""
    if kin_delta is None:
        return None
    arr = np.asarray(kin_delta, dtype=np.float64)
    m = 5 * chain.n
    if arr.shape != (m,) and arr.shape != (N, m):
        raise InputError(f"{name}: expected shape ({N}, {m}) or ({m},), got {arr.shape}")
    return arr


def _fixed_factor(
    convention: str,
    a: FloatArray,
    d: FloatArray,
    ca: FloatArray,
    sa: FloatArray,
    cb: FloatArray,
    sb: FloatArray,
) -> FloatArray:
    """The q-independent factor of every joint transform, entries first: ``(4, 4, *S)``.

    ``M = Rx(alpha) Ry(beta)`` has rows ``[cb, 0, sb]``, ``[sa sb, ca, -sa cb]``,
    ``[-ca sb, sa, ca cb]``. DH: ``F = Tz(d) Tx(a) M = [M, (a, 0, d)]``; MDH:
    ``F = M Tx(a) = [M, a M e_x]``. ``S`` is the broadcast shape of the inputs
    (``(n,)`` or ``(n, N)``).
    """
    shape = np.broadcast_shapes(a.shape, d.shape, ca.shape, cb.shape)
    F = np.zeros((4, 4) + shape)
    F[0, 0] = cb
    F[0, 2] = sb
    F[1, 0] = sa * sb
    F[1, 1] = ca
    F[1, 2] = -sa * cb
    F[2, 0] = -ca * sb
    F[2, 1] = sa
    F[2, 2] = ca * cb
    if convention == "dh":
        F[0, 3] = a
        F[2, 3] = d
    else:
        F[0, 3] = a * F[0, 0]
        F[1, 3] = a * F[1, 0]
        F[2, 3] = a * F[2, 0]
    F[3, 3] = 1.0
    return F


def forward(chain: Chain, q: ArrayLike, kin_delta: ArrayLike | None = None) -> ChainPoses:
    """Link frames of ``chain`` at joint angles ``q``.

    Args:
        chain: the kinematic chain.
        q: joint angles (rad), shape ``(N, n)``.
        kin_delta: deltas added to the nominal kinematic parameters, laid out
            ``[theta, d, a, alpha, beta]`` (rad, m), shape ``(N, 5n)`` (per pose) or
            ``(5n,)`` (shared), or None for the nominal chain.

    Returns:
        :class:`ChainPoses` with ``T_base_link`` of shape ``(N, n+1, 4, 4)``.
    """
    q = check_q(chain, q)
    N, n = q.shape
    delta = check_kin_delta(chain, kin_delta, N)

    # Row values joint-first: theta is (n, N); d, a, alpha, beta are (n,) when shared by
    # all poses and (n, N) when they vary per pose.
    prismatic = chain.joint_is_prismatic
    any_prismatic = bool(prismatic.any())
    if any_prismatic and delta is not None:
        # Move the joint-variable slot of prismatic joints to a translation ``slide`` and
        # their d slot (the fixed rotation about the axis) into theta: after the swap below
        # the delta reads as for a revolute table, with a zero d delta on prismatic rows.
        delta = delta.copy()
        joint_slot = delta[..., :n][..., prismatic].copy()
        delta[..., :n][..., prismatic] = delta[..., n:2 * n][..., prismatic]
        delta[..., n:2 * n][..., prismatic] = joint_slot
        slide_delta = np.where(prismatic[:, None], np.atleast_2d(delta[..., n:2 * n]).T, 0.0)
        delta[..., n:2 * n][..., prismatic] = 0.0
    else:
        slide_delta = np.zeros((n, 1))
    slide = np.where(prismatic[:, None], q.T + slide_delta, 0.0)  # (n, N), m
    theta = chain.theta[:, None] + np.where(prismatic[:, None], 0.0, q.T)
    fixed_delta: FloatArray | None = None  # d, a, alpha, beta deltas: (4, n) or (4, n, N)
    if delta is not None and delta.ndim == 1:
        theta += delta[:n, None]
        fixed_delta = delta[n:].reshape(4, n)
    elif delta is not None:
        theta += delta[:, :n].T
        rest = delta[:, n:]
        if N > 0 and np.array_equal(rest, np.broadcast_to(rest[0], rest.shape)):
            # Only the joint angles vary per pose (joint-space effects): keep the fixed
            # factors shared, which is several times faster.
            fixed_delta = rest[0].reshape(4, n)
        else:
            fixed_delta = rest.T.reshape(4, n, N)
    d, a, alpha, beta = chain.d, chain.a, chain.alpha, chain.beta
    per_pose = fixed_delta is not None and fixed_delta.ndim == 3
    if fixed_delta is not None:
        if per_pose:
            d, a, alpha, beta = d[:, None], a[:, None], alpha[:, None], beta[:, None]
        d = d + fixed_delta[0]
        a = a + fixed_delta[1]
        alpha = alpha + fixed_delta[2]
        beta = beta + fixed_delta[3]
    ct, st = np.cos(theta), np.sin(theta)
    ca, sa = np.cos(alpha), np.sin(alpha)
    cb, sb = np.cos(beta), np.sin(beta)
    F = _fixed_factor(chain.convention, a, d, ca, sa, cb, sb)
    # Shared factors, transposed for the product below: F_T[i] = F_i^T, (n, 4, 4).
    F_T = None if per_pose else np.ascontiguousarray(F.transpose(2, 1, 0))

    Tc = np.empty((n + 1, 4, 4, N))  # Tc[i, row, col, pose]
    Tc[:, 3, :3] = 0.0
    Tc[:, 3, 3] = 1.0
    assert chain.T_base_link0 is not None
    Tc[0, :3] = chain.T_base_link0[:3, :, None]
    work = np.empty((3, 4, N))
    for i in range(n):
        prev, nxt = Tc[i, :3], Tc[i + 1, :3]  # (3, 4, N): rows 0..2 of T_base_link_i
        c, s = ct[i], st[i]
        if chain.convention == "dh":
            # work = T_{i} Rz(theta): x, y columns turn by theta; then T_{i+1} = work F_i.
            np.multiply(prev[:, 0], c, out=work[:, 0])
            work[:, 0] += prev[:, 1] * s
            np.multiply(prev[:, 1], c, out=work[:, 1])
            work[:, 1] -= prev[:, 0] * s
            work[:, 2:] = prev[:, 2:]
            if prismatic[i]:
                work[:, 3] += work[:, 2] * slide[i]
            _times_fixed(work, F, F_T, i, out=nxt)
        else:
            # work = T_{i} F_i; then T_{i+1} = work Rz(theta) Tz(d).
            _times_fixed(prev, F, F_T, i, out=work)
            np.multiply(work[:, 0], c, out=nxt[:, 0])
            nxt[:, 0] += work[:, 1] * s
            np.multiply(work[:, 1], c, out=nxt[:, 1])
            nxt[:, 1] -= work[:, 0] * s
            nxt[:, 2] = work[:, 2]
            np.multiply(work[:, 2], d[i] + slide[i] if prismatic[i] else d[i], out=nxt[:, 3])
            nxt[:, 3] += work[:, 3]

    shape = (N, n)
    return ChainPoses(
        convention=chain.convention,
        T_base_link=Tc.transpose(3, 0, 1, 2),
        cos_theta=ct.T,
        sin_theta=st.T,
        cos_alpha=np.broadcast_to(ca.T if per_pose else ca, shape),
        sin_alpha=np.broadcast_to(sa.T if per_pose else sa, shape),
        cos_beta=np.broadcast_to(cb.T if per_pose else cb, shape),
        sin_beta=np.broadcast_to(sb.T if per_pose else sb, shape),
        T_link_flange=chain.T_link_flange if chain.has_mounts else None,
    )


def _times_fixed(
    frame: FloatArray, F: FloatArray, F_T: FloatArray | None, i: int, out: FloatArray
) -> None:
    """``out = frame @ F_i`` for component-major ``frame`` and ``out`` of shape ``(3, 4, N)``.

    With a shared factor (``F_T`` given, ``(n, 4, 4)``) this is one small matrix product;
    with a per-pose factor (``F`` of shape ``(4, 4, n, N)``) a sum over the inner index.
    """
    if F_T is not None:
        np.matmul(F_T[i], frame, out=out)
        return
    F_i = F[:, :, i]  # (4, 4, N)
    np.multiply(frame[:, 0, None, :], F_i[0], out=out)
    for k in range(1, 4):
        out += frame[:, k, None, :] * F_i[k]
