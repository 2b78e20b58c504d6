"""Closed-form initial estimates of the sphere_probe frames (pure numerics).

The touch-probe procedure (docs/sphere-probe.md) touches a reference sphere of radius R with a
stylus ball of radius r, 5 times per probe orientation. At a contact the stylus tip centre is
at the contact distance rho = R + r from the sphere centre:

    | R_base_flange P_t + t_base_flange - P_b | = rho                        (S11)

with ``T_base_flange = [R_base_flange, t_base_flange]`` from forward kinematics of the
latched joint angles, ``P_t`` the stylus tip centre in the flange frame and ``P_b`` the
sphere centre in the base frame (all in metres). For a fixed flange rotation ``R_k`` the
flange origins of the group's contacts lie on a sphere of radius rho around ``P_c,k = P_b -
R_k P_t`` (S4); the ``P_c,k`` of all orientations lie on a sphere of radius |P_t| around
``P_b`` (S7); ``P_t`` follows from one orientation: ``P_t = R_1^T (P_b - P_c,1)`` (S8-S9).

These estimates ignore the joint offsets: they are the starting frames of the joint solve
(hostpc.fit), which estimates offsets, P_b and P_t together. Here we add two refinements of
the patent's steps: a linear least-squares solve of ``P_b - R_k P_t = P_c,k`` over all
orientations, then Gauss-Newton on the contact distances (S11) with the joints held, which
also absorbs the small rotation of the flange within a group (a guarded move follows a
joint-space line, so the flange rotation at contact differs slightly between contacts).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

MIN_POINTS_FREE_RADIUS = 4
MIN_POINTS_KNOWN_RADIUS = 3


class SphereFitError(ValueError):
    """The points do not determine a sphere (too few, or degenerate: coplanar, collinear)."""


@dataclass(frozen=True)
class SphereFit:
    """A least-squares sphere: centre (3,) m, radius m, rms of the geometric residuals
    |x_i - centre| - radius (m), and the residuals (K,) themselves."""

    centre: np.ndarray
    radius: float
    rms: float
    residuals: np.ndarray


def _algebraic_sphere(points: np.ndarray) -> tuple[np.ndarray, float]:
    """Kasa fit: |x|^2 = 2 c.x + k, linear in (c, k); radius = sqrt(k + |c|^2)."""
    # centred for conditioning
    mean = points.mean(axis=0)
    shifted = points - mean
    A = np.column_stack([2.0 * shifted, np.ones(points.shape[0])])
    b = np.sum(shifted**2, axis=1)
    solution, _, rank, _ = np.linalg.lstsq(A, b, rcond=None)
    if rank < 4:
        raise SphereFitError("points are coplanar: the sphere is not determined")
    centre = solution[:3] + mean
    radius_sq = solution[3] + float(solution[:3] @ solution[:3])
    return centre, float(np.sqrt(max(radius_sq, 0.0)))


def fit_sphere(points: np.ndarray, radius: float | None = None, *,
               centre_guess: np.ndarray | None = None, iterations: int = 50) -> SphereFit:
    """Least-squares sphere through points (K, 3) (m).

    radius None: centre and radius are estimated (K >= 4, not coplanar): algebraic (Kasa)
    fit, then Gauss-Newton on the geometric residuals. radius given (m): only the centre
    (K >= 3); the start is the algebraic fit if K >= 4, else centre_guess, else the centroid
    shifted along the normal of the points' plane. On a cap of a sphere the known radius is
    much better conditioned than a free one; with it, the centre is taken on the side of
    centre_guess (if given) or of the free fit.
    """
    points = np.asarray(points, dtype=float)
    if points.ndim != 2 or points.shape[1] != 3:
        raise SphereFitError(f"points must have shape (K, 3), got {points.shape}")
    k = points.shape[0]
    needed = MIN_POINTS_FREE_RADIUS if radius is None else MIN_POINTS_KNOWN_RADIUS
    if k < needed:
        raise SphereFitError(f"{k} points cannot determine a sphere (need at least {needed})")
    if centre_guess is not None:
        centre = np.asarray(centre_guess, dtype=float).copy()
        r = float(radius) if radius is not None else float(
            np.mean(np.linalg.norm(points - centre, axis=1)))
    elif k >= MIN_POINTS_FREE_RADIUS:
        try:
            centre, r = _algebraic_sphere(points)
        except SphereFitError:
            if radius is None:
                raise
            centre, r = _plane_guess(points, float(radius))
    else:
        assert radius is not None
        centre, r = _plane_guess(points, float(radius))
    if radius is not None:
        r = float(radius)
    for _ in range(iterations):
        diff = points - centre
        dist = np.linalg.norm(diff, axis=1)
        if np.any(dist < 1e-15):
            raise SphereFitError("a point coincides with the centre estimate")
        u = diff / dist[:, None]
        residual = dist - r
        J = -u if radius is not None else np.column_stack([-u, -np.ones(k)])
        step, _, rank, _ = np.linalg.lstsq(J, -residual, rcond=None)
        if rank < J.shape[1]:
            raise SphereFitError("points are degenerate (collinear or coplanar)")
        centre = centre + step[:3]
        if radius is None:
            r = float(r + step[3])
        if np.linalg.norm(step) < 1e-13:
            break
    residuals = np.linalg.norm(points - centre, axis=1) - r
    return SphereFit(centre=centre, radius=abs(r), rms=float(np.sqrt(np.mean(residuals**2))),
                     residuals=residuals)


def _plane_guess(points: np.ndarray, radius: float) -> tuple[np.ndarray, float]:
    """Centre of a sphere of `radius` through the plane of the points, on its normal."""
    mean = points.mean(axis=0)
    _, _, Vt = np.linalg.svd(points - mean)
    normal = Vt[2]
    spread = float(np.mean(np.linalg.norm(points - mean, axis=1) ** 2))
    height = np.sqrt(max(radius**2 - spread, 0.0))
    return mean - height * normal, radius


def mean_rotation(R: np.ndarray) -> np.ndarray:
    """Chordal mean (3, 3) of rotations (K, 3, 3): the rotation nearest to their sum."""
    U, _, Vt = np.linalg.svd(np.sum(R, axis=0))
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])
    mean: np.ndarray = U @ D @ Vt
    return mean


@dataclass(frozen=True)
class OrientationCentre:
    """S4 for one probe orientation: group index, P_c (3,) base frame (m), the group's mean
    flange rotation R_base_flange (3, 3), the number of contacts and the sphere-fit rms (m)."""

    group: int
    centre: np.ndarray
    rotation: np.ndarray
    n_contacts: int
    rms: float


def orientation_centres(T_base_flange: np.ndarray, groups: np.ndarray,
                        contact_distance: float) -> list[OrientationCentre]:
    """S4: P_c per probe orientation from the flange origins of its contacts.

    T_base_flange: (N, 4, 4) flange poses at the latched angles (nominal model); groups: (N,)
    orientation index per contact; contact_distance: R + r (m). Groups with fewer than 3
    contacts (or degenerate ones) are skipped. Sorted by group index.
    """
    groups = np.asarray(groups)
    out: list[OrientationCentre] = []
    for g in np.unique(groups):
        rows = np.flatnonzero(groups == g)
        if g < 0 or rows.size < MIN_POINTS_KNOWN_RADIUS:
            continue
        origins = T_base_flange[rows, :3, 3]
        rotation = mean_rotation(T_base_flange[rows, :3, :3])
        try:
            result = fit_sphere(origins, contact_distance, centre_guess=None)
        except SphereFitError:
            continue
        out.append(OrientationCentre(int(g), result.centre, rotation, int(rows.size),
                                     result.rms))
    return out


@dataclass(frozen=True)
class InitialEstimate:
    """Closed-form starting frames of the joint solve.

    sphere_centre: P_b (3,) base frame (m); tip: P_t (3,) flange frame (m);
    patent_sphere_centre / patent_tip: the same from the patent's steps alone (S7, S8-S9),
    before refinement; centres: the per-orientation P_c (S4); rms: rms of the contact
    distance residuals (m) with these frames and the joints as latched.
    """

    sphere_centre: np.ndarray
    tip: np.ndarray
    patent_sphere_centre: np.ndarray
    patent_tip: np.ndarray
    centres: tuple[OrientationCentre, ...]
    rms: float


def tip_and_centre_linear(centres: np.ndarray, rotations: np.ndarray,
                          sphere_centre: np.ndarray | None = None
                          ) -> tuple[np.ndarray, np.ndarray]:
    """Least squares of P_b - R_k P_t = P_c,k over orientations k.

    centres: (G, 3) P_c; rotations: (G, 3, 3) R_k. sphere_centre: if given (3,), P_b is held
    (known sphere) and only P_t is solved. Returns (P_b (3,), P_t (3,)).
    """
    G = centres.shape[0]
    if sphere_centre is not None:
        # P_t = R_k^T (P_b - P_c,k), averaged (least squares, R_k orthonormal)
        tip = np.mean(np.einsum("gji,gj->gi", rotations, sphere_centre - centres), axis=0)
        return np.asarray(sphere_centre, float).copy(), tip
    A = np.zeros((3 * G, 6))
    A[:, :3] = np.tile(np.eye(3), (G, 1))
    A[:, 3:] = -rotations.reshape(3 * G, 3)
    solution, _, rank, _ = np.linalg.lstsq(A, centres.reshape(-1), rcond=None)
    if rank < 6:
        raise SphereFitError("probe orientations too similar to separate P_b from P_t")
    return solution[:3], solution[3:]


def refine_contacts(T_base_flange: np.ndarray, contact_distance: float, sphere_centre: np.ndarray,
                    tip: np.ndarray, *, hold_sphere: bool = False, hold_tip: bool = False,
                    iterations: int = 30) -> tuple[np.ndarray, np.ndarray, float]:
    """Gauss-Newton on the contact distances |R_i P_t + t_i - P_b| - rho (S11), joints held.

    T_base_flange: (N, 4, 4); contact_distance: rho (m); sphere_centre: P_b (3,) and tip: P_t
    (3,) start values (m). Returns (P_b, P_t, rms residual (m)).
    """
    R, t = T_base_flange[:, :3, :3], T_base_flange[:, :3, 3]
    centre, tip = np.asarray(sphere_centre, float).copy(), np.asarray(tip, float).copy()
    free = [not hold_sphere] * 3 + [not hold_tip] * 3
    for _ in range(iterations):
        diff = np.einsum("nij,j->ni", R, tip) + t - centre
        dist = np.linalg.norm(diff, axis=1)
        u = diff / dist[:, None]
        residual = dist - contact_distance
        J = np.column_stack([-u, np.einsum("ni,nij->nj", u, R)])[:, free]
        if J.shape[1] == 0:
            break
        step, *_ = np.linalg.lstsq(J, -residual, rcond=None)
        full = np.zeros(6)
        full[free] = step
        centre += full[:3]
        tip += full[3:]
        if np.linalg.norm(step) < 1e-12:
            break
    diff = np.einsum("nij,j->ni", R, tip) + t - centre
    residual = np.linalg.norm(diff, axis=1) - contact_distance
    return centre, tip, float(np.sqrt(np.mean(residual**2)))


def initial_estimate(T_base_flange: np.ndarray, groups: np.ndarray, contact_distance: float,
                     *, known_sphere_centre: np.ndarray | None = None,
                     known_tip: np.ndarray | None = None) -> InitialEstimate:
    """P_b and P_t from contacts grouped by probe orientation (S4, S7, S8-S9 + refinement).

    T_base_flange: (N, 4, 4) flange poses at the latched angles; groups: (N,) orientation
    per contact; contact_distance: R + r (m). known_sphere_centre / known_tip: (3,) frames
    held at a trusted value (the dataset's `known`). Needs at least 2 orientations with 3+
    contacts (S7's sphere fit needs 4 P_c when neither frame is known).
    """
    centres = orientation_centres(T_base_flange, groups, contact_distance)
    if len(centres) < 2:
        raise SphereFitError(
            f"{len(centres)} usable probe orientations: need at least 2 with 3+ contacts")
    P_c = np.array([c.centre for c in centres])
    R_k = np.array([c.rotation for c in centres])
    if known_sphere_centre is not None:
        patent_centre = np.asarray(known_sphere_centre, float)
    elif known_tip is not None:
        patent_centre = np.mean(P_c + np.einsum("gij,j->gi", R_k, known_tip), axis=0)
    else:
        if len(centres) < MIN_POINTS_FREE_RADIUS:
            raise SphereFitError(f"{len(centres)} probe orientations: S7 needs at least 4")
        patent_centre = fit_sphere(P_c).centre  # S7
    patent_tip = (np.asarray(known_tip, float) if known_tip is not None
                  else R_k[0].T @ (patent_centre - P_c[0]))  # S8-S9
    if known_tip is not None:
        centre, tip = patent_centre, np.asarray(known_tip, float)
    else:
        centre, tip = tip_and_centre_linear(P_c, R_k, known_sphere_centre)
    centre, tip, rms = refine_contacts(
        T_base_flange, contact_distance, centre, tip,
        hold_sphere=known_sphere_centre is not None, hold_tip=known_tip is not None)
    return InitialEstimate(sphere_centre=centre, tip=tip, patent_sphere_centre=patent_centre,
                           patent_tip=patent_tip, centres=tuple(centres), rms=rms)
