"""Touch probe: the stylus tip sphere touching the reference sphere.

A guarded move runs along the straight joint-space path (reported angles)
`q(s) = q_start + s (q_target - q_start)`, s in [0, 1], at constant joint speed, so simulated
time is `t = s * duration`. The stylus touches the sphere when

    |tip_base(q_phys(s)) - P_b| = R_sphere + r_stylus (+ repeatability noise),

found by adaptive sampling (segments that provably cannot touch are skipped) then
bisection to 1e-9 m. All positions are in the base frame (m).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

CONTACT_TOL_M = 1e-9
_MIN_STEP_M = 1e-4  # final sampling step: at most this much tip travel between samples
_COARSE = 64  # first sampling of the path
_SPLIT = 16  # subdivision of a segment that may touch the sphere

GapFunction = Callable[[np.ndarray], np.ndarray]
"""(K,) path parameters s -> (K,) gap |tip - P_b| - contact distance (m); < 0 inside."""


@dataclass(frozen=True)
class Crossing:
    """A sign change of the gap along the path: s at the boundary, rising = entering."""

    s: float
    rising: bool


def bisect_boundary(
    gap: GapFunction, s_lo: float, s_hi: float, tol_m: float = CONTACT_TOL_M
) -> float:
    """s in [s_lo, s_hi] where the gap changes sign, to |gap| <= tol_m.

    gap(s_lo) and gap(s_hi) must have opposite signs (<= 0 counts as inside).
    """
    inside_lo = float(gap(np.array([s_lo]))[0]) <= 0.0
    for _ in range(200):
        s_mid = 0.5 * (s_lo + s_hi)
        g_mid = float(gap(np.array([s_mid]))[0])
        if abs(g_mid) <= tol_m or s_hi - s_lo < 1e-16:
            return s_mid
        if (g_mid <= 0.0) == inside_lo:
            s_lo = s_mid
        else:
            s_hi = s_mid
    return 0.5 * (s_lo + s_hi)


def find_crossings(
    gap: GapFunction, lipschitz_m: float, min_step_m: float = _MIN_STEP_M
) -> list[Crossing]:
    """All boundary crossings along s in [0, 1], in path order.

    lipschitz_m bounds |d gap / d s| (m per unit s: the tip cannot move faster along the
    path). A segment whose end gaps g0, g1 have the same sign and |g0 + g1| > L ds cannot
    cross the boundary and is dropped; the others are subdivided until the tip moves at
    most min_step_m per segment, then every sign change is bisected to 1e-9 m. Only a
    graze thinner than min_step_m of tip travel can be missed (as a real switch would).
    """
    L = max(float(lipschitz_m), 1e-12)
    s = np.linspace(0.0, 1.0, _COARSE + 1)
    g = gap(s)
    lo, hi, g_lo, g_hi = s[:-1], s[1:], g[:-1], g[1:]
    brackets: list[tuple[float, float]] = []
    while lo.size:
        ds = hi - lo
        inside_lo, inside_hi = g_lo <= 0.0, g_hi <= 0.0
        changes = inside_lo != inside_hi
        # same side at both ends: a double crossing needs |g0 + g1| <= L ds
        candidate = changes | (np.abs(g_lo + g_hi) <= L * ds)
        final = L * ds <= min_step_m
        for k in np.nonzero(candidate & final & changes)[0]:
            brackets.append((float(lo[k]), float(hi[k])))
        keep = candidate & ~final
        lo, hi, g_lo, g_hi = lo[keep], hi[keep], g_lo[keep], g_hi[keep]
        if not lo.size:
            break
        # split every kept segment into _SPLIT parts, evaluated in one batch
        frac = np.linspace(0.0, 1.0, _SPLIT + 1)
        pts = lo[:, None] + (hi - lo)[:, None] * frac[None, :]
        inner = gap(pts[:, 1:-1].ravel()).reshape(lo.size, _SPLIT - 1)
        gs = np.concatenate([g_lo[:, None], inner, g_hi[:, None]], axis=1)
        lo, hi = pts[:, :-1].ravel(), pts[:, 1:].ravel()
        g_lo, g_hi = gs[:, :-1].ravel(), gs[:, 1:].ravel()
    brackets.sort()
    crossings = []
    for s_lo, s_hi in brackets:
        entering = float(gap(np.array([s_hi]))[0]) <= 0.0
        crossings.append(Crossing(s=bisect_boundary(gap, s_lo, s_hi), rising=entering))
    return crossings


def tip_positions(T_base_flange: np.ndarray, tip_flange: np.ndarray) -> np.ndarray:
    """(N, 4, 4) flange poses and (3,) tip in flange (m) -> (N, 3) tip centres in base."""
    return np.einsum("nij,j->ni", T_base_flange[:, :3, :3], tip_flange) + T_base_flange[:, :3, 3]


class TouchProbe:
    """The touch probe of one simulation: the stylus on the flange and the reference sphere.

    tip_flange: (3,) true stylus tip centre in the flange frame (m); sphere_centre: (3,) true
    sphere centre in base (m); sphere_radius, stylus_radius: m; io_line: the digital input
    the probe switches.
    """

    def __init__(self, tip_flange: np.ndarray, sphere_centre: np.ndarray,
                 sphere_radius: float, stylus_radius: float, io_line: int) -> None:
        self.tip_flange = tip_flange
        self.sphere_centre = sphere_centre
        self.sphere_radius = sphere_radius
        self.stylus_radius = stylus_radius
        self.io_line = io_line

    def tips(self, T_base_flange: np.ndarray) -> np.ndarray:
        """(N, 4, 4) flange poses -> (N, 3) tip centres in base (m)."""
        return tip_positions(T_base_flange, self.tip_flange)

    def gaps(self, T_base_flange: np.ndarray, extra: float = 0.0) -> np.ndarray:
        """(N, 4, 4) flange poses -> (N,) gap |tip - P_b| - (R + r + extra) (m), < 0 inside."""
        contact = self.sphere_radius + self.stylus_radius + extra
        return np.linalg.norm(self.tips(T_base_flange) - self.sphere_centre, axis=1) - contact

    def touching(self, T_base_flange: np.ndarray) -> bool:
        """True if the stylus touches the sphere at the flange pose (4, 4)."""
        tip = self.tips(T_base_flange[None])[0]
        reach = self.sphere_radius + self.stylus_radius
        return bool(np.linalg.norm(tip - self.sphere_centre) <= reach)
