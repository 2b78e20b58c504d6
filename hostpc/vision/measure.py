"""Target measurement, the one entry point the acquisition methods use (S202-S205).

    measurer = TargetMeasurer(rig, target_radius=0.01)           # once per rig
    result = measurer.measure(left, right)                       # per stereo pair
    if isinstance(result, TargetRejected): ...                   # result.reason, one line
    else: result.p (3,), result.cov (3, 3)                       # left camera frame, m, m^2

Pipeline: detect the dark disk in both RAW images (`target_detection`), triangulate the two
intensity centroids through the rectified geometry (`triangulation`), estimate the plate
normal, correct the perspective bias of both centroids (the area centroid of a projected
disk is not the projection of its centre), re-triangulate, check plausibility, and
propagate the pixel covariance. With depth="sgbm" the depth comes instead from an SGBM
disparity map sampled at the centre (`disparity`).

Perspective bias. For the current estimate of the centre C and normal n, the disk model
(`disk_image_moments`) gives in each camera the area centroid of the projected disk and the
projection of C; their difference (up to ~0.3 px at 0.5 m for a 10 mm disk tilted 30 deg,
~0.7 px at 0.3 m) is subtracted from the measured centroid, and the point re-triangulated
(one round suffices: the bias is smooth in C). The normal comes from `normal_hint` if given, else
from a fit to what the images show: the anisotropy of the disk's second moments in both
cameras (blur-free: isotropic blur cancels in mu_xx - mu_yy and mu_xy) and the offset of
the bright plate's centroid from the disk's (perspective shifts the plate's centroid ~25x
more than the disk's, which fixes the sign of the tilt that the ellipse shape alone cannot).
The bias moves about 0.01 px per degree of normal error.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np

from hostpc.errors import InputError
from hostpc.vision.disparity import SampledDisparity, sgbm_disparity_at
from hostpc.vision.rectification import Rectification, rectification_for
from hostpc.vision.rig import StereoRig
from hostpc.vision.target_detection import DetectionFailure, DiskBlob, detect_disk
from hostpc.vision.triangulation import (
    CameraModel,
    DiskImage,
    Triangulated,
    disk_image_moments,
    plane_axes,
    propagate_covariance,
    triangulate,
)

DepthMethod = Literal["triangulate", "sgbm"]

EPIPOLAR_TOLERANCE_PX = 1.5
"""Largest |y_left - y_right| of the rectified centres (px) of a consistent detection."""
AREA_TOLERANCE = 0.25
"""Largest relative difference between the measured and the expected disk image area."""
MIN_DEPTH, MAX_DEPTH = 0.05, 5.0
"""Plausible target depths (m)."""
_NORMAL_STARTS = np.array([[0.0, 0.0], [0.35, 0.0], [-0.35, 0.0], [0.0, 0.35], [0.0, -0.35]])
_FIT_SAMPLES = 32
_FIT_ITERATIONS = 4


@dataclass(frozen=True, eq=False)
class TargetObservation:
    """One measured target centre.

    p: (3,) disk centre in the left camera's optical frame (m).
    cov: (3, 3) its covariance (m^2) from the pixel-centre noise.
    uv: (2, 2) [[u_l, v_l], [u_r, v_r]] raw-image pixels of the disk centre (the
        projection of the centre: measured centroid minus perspective bias).
    depth_method: "triangulate" or "sgbm".
    normal: (3,) unit plate normal used for the bias correction (left frame, towards the
        camera), or None.
    uv_centroid: (2, 2) the measured intensity centroids before the bias correction (px).
    """

    p: np.ndarray
    cov: np.ndarray
    uv: np.ndarray
    depth_method: str
    normal: np.ndarray | None = None
    uv_centroid: np.ndarray | None = None


@dataclass(frozen=True)
class TargetRejected:
    """The pair gave no trustworthy measurement; `reason` is one line."""

    reason: str


class TargetMeasurer:
    """Measures the target centre in stereo pairs taken with `rig`.

    target_radius: radius of the dark disk (m).
    depth: "triangulate" (the default: centre-based) or "sgbm" (disparity map).
    pixel_sigma: standard deviation (px) of each detected centre coordinate; None estimates
        it per image from the pixel noise on the plate (exact propagation through the
        centroid, typically 0.005-0.01 px for the simulator's images). Pass e.g. 0.05 to
        fold calibration systematics into the covariance.
    """

    def __init__(
        self,
        rig: StereoRig,
        target_radius: float,
        depth: DepthMethod = "triangulate",
        pixel_sigma: float | None = None,
    ) -> None:
        if not (math.isfinite(target_radius) and target_radius > 0.0):
            raise InputError(f"target_radius: expected a positive length in m, got {target_radius}")
        if depth not in ("triangulate", "sgbm"):
            raise InputError(f"depth: expected 'triangulate' or 'sgbm', got {depth!r}")
        if pixel_sigma is not None and not (math.isfinite(pixel_sigma) and pixel_sigma > 0.0):
            raise InputError(f"pixel_sigma: expected a positive value in px, got {pixel_sigma}")
        self.rig = rig
        self.target_radius = float(target_radius)
        self.depth: DepthMethod = depth
        self.pixel_sigma = pixel_sigma
        self.rect: Rectification = rectification_for(rig)
        self._cameras = (
            CameraModel(rig.K_left, rig.dist_left, np.eye(3), np.zeros(3)),
            CameraModel(rig.K_right, rig.dist_right, rig.R, rig.T),
        )

    # ------------------------------------------------------------------ entry point

    def measure(
        self, left: np.ndarray, right: np.ndarray, normal_hint: np.ndarray | None = None
    ) -> TargetObservation | TargetRejected:
        """Measure the target centre in one raw stereo pair (H, W) uint8 each.

        normal_hint: optional (3,) plate normal in the left camera frame (e.g. from the
        nominal target normal and camera pose); skips the normal estimate.
        Raises InputError if the images do not match the rig (size, type).
        """
        left = self._check_image(left, "left")
        right = self._check_image(right, "right")
        blobs: list[DiskBlob] = []
        for name, image in (("left", left), ("right", right)):
            found = detect_disk(image, self.pixel_sigma)
            if isinstance(found, DetectionFailure):
                return TargetRejected(f"{found.reason} in the {name} image")
            blobs.append(found)
        blob_l, blob_r = blobs
        tri = triangulate(self.rect, blob_l.centroid, blob_r.centroid)
        rejected = self._check_geometry(tri)
        if rejected is not None:
            return rejected
        if normal_hint is not None:
            normal = np.asarray(normal_hint, dtype=float).reshape(3)
            normal = normal / np.linalg.norm(normal)
        else:
            normal = self._estimate_normal(tri.p, blob_l, blob_r)
        centroids = np.stack([blob_l.centroid, blob_r.centroid])
        # one round suffices: the bias changes by ~1e-4 px when C moves by the correction
        images = self._disk_images(tri.p[None, :], normal[None, :], self.target_radius)
        uv = centroids - np.stack([images[0].bias[0], images[1].bias[0]])
        tri = triangulate(self.rect, uv[0], uv[1])
        rejected = self._check_geometry(tri)
        if rejected is not None:
            return rejected
        for name, blob, disk in (("left", blob_l, images[0]), ("right", blob_r, images[1])):
            expected = float(disk.area[0])
            if abs(blob.area / expected - 1.0) > AREA_TOLERANCE:
                return TargetRejected(
                    f"implausible disk size in the {name} image: {blob.area:.0f} px^2, "
                    f"expected {expected:.0f} px^2 for radius {1e3 * self.target_radius:g} mm "
                    f"at {tri.p[2]:.3f} m"
                )
        cov = propagate_covariance(tri.dp_duv, blob_l.centroid_cov, blob_r.centroid_cov)
        if self.depth == "sgbm":
            return self._sgbm(left, right, tri, blob_l, uv, normal, centroids)
        return TargetObservation(
            p=tri.p, cov=cov, uv=uv, depth_method="triangulate", normal=normal,
            uv_centroid=centroids,
        )

    # ------------------------------------------------------------------ helpers

    def _check_image(self, image: np.ndarray, name: str) -> np.ndarray:
        image = np.asarray(image)
        w, h = self.rig.image_size
        if image.ndim != 2 or image.dtype != np.uint8:
            raise InputError(
                f"{name} image: expected (H, W) uint8, got {image.shape} {image.dtype}"
            )
        if image.shape != (h, w):
            raise InputError(
                f"{name} image: size {image.shape[1]}x{image.shape[0]} does not match the "
                f"rig's {w}x{h}"
            )
        return np.ascontiguousarray(image)

    def _check_geometry(self, tri: Triangulated) -> TargetRejected | None:
        if abs(tri.dy) > EPIPOLAR_TOLERANCE_PX:
            return TargetRejected(
                f"left and right detections disagree with the epipolar constraint "
                f"(rectified rows differ by {tri.dy:+.2f} px)"
            )
        if tri.disparity <= 0 or not (MIN_DEPTH <= tri.p[2] <= MAX_DEPTH):
            return TargetRejected(
                f"implausible target depth (disparity {tri.disparity:.1f} px)"
            )
        return None

    def _disk_images(self, centres: np.ndarray, normals: np.ndarray, radii: np.ndarray | float,
                     n_samples: int = 96) -> list[DiskImage]:
        """Disk image moments in [left, right] for batched centres/normals (B, 3)."""
        return disk_image_moments(self._cameras, centres, normals, radii, n_samples)

    def _estimate_normal(self, p: np.ndarray, blob_l: DiskBlob, blob_r: DiskBlob) -> np.ndarray:
        """Plate normal (3,) (left frame, towards the cameras) fitted to the disk's moment
        anisotropy and the plate centroid offset in both images (Gauss-Newton from five
        starts, the lowest cost wins)."""
        n0 = -p / np.linalg.norm(p)
        e1, e2 = (v[0] for v in plane_axes(n0[None, :]))
        blobs = (blob_l, blob_r)
        plate_radii = [
            self.target_radius * math.sqrt(b.plate_area / b.area)
            for b in blobs
            if b.plate_area is not None and b.plate_offset is not None
        ]
        use_plate = bool(plate_radii)
        radii = [self.target_radius] + ([float(np.mean(plate_radii))] if use_plate else [])

        def anisotropy(m: np.ndarray) -> np.ndarray:
            return np.stack([m[..., 0, 0] - m[..., 1, 1], 2.0 * m[..., 0, 1]], axis=-1)

        measured = [anisotropy(b.moments) for b in blobs]
        sigma_a = [0.3 + 0.01 * float(np.trace(b.moments)) for b in blobs]

        def residuals(ab: np.ndarray) -> np.ndarray:
            """(S, m) whitened residuals for parameter rows ab (S, 2)."""
            s = len(ab)
            normals = n0 + ab[:, :1] * e1 + ab[:, 1:] * e2
            normals /= np.linalg.norm(normals, axis=1, keepdims=True)
            k = len(radii)
            images = self._disk_images(
                np.broadcast_to(p, (k * s, 3)),
                np.tile(normals, (k, 1)),
                np.repeat(radii, s),
                _FIT_SAMPLES,
            )
            parts = []
            for cam, blob in enumerate(blobs):
                disk = images[cam]
                parts.append((measured[cam] - anisotropy(disk.moments[:s])) / sigma_a[cam])
                if use_plate and blob.plate_offset is not None:
                    predicted = disk.centroid[s:] - disk.centroid[:s]
                    sigma_o = 0.3 + 0.1 * float(np.linalg.norm(blob.plate_offset))
                    parts.append((blob.plate_offset - predicted) / sigma_o)
            return np.concatenate(parts, axis=1)

        # the plate offset fixes the sign of the tilt: one start suffices; without it the
        # ellipse shape alone has two minima, so start from five tilts
        ab = _NORMAL_STARTS[:1].copy() if use_plate else _NORMAL_STARTS.copy()
        step = 1e-4
        for _ in range(_FIT_ITERATIONS):
            s = len(ab)
            r_all = residuals(np.concatenate([ab, ab + [step, 0.0], ab + [0.0, step]]))
            r0 = r_all[:s]
            J = np.stack([(r_all[s : 2 * s] - r0) / step, (r_all[2 * s :] - r0) / step], axis=2)
            JtJ = np.einsum("smi,smj->sij", J, J) + 1e-6 * np.eye(2)
            Jtr = np.einsum("smi,sm->si", J, r0)
            delta = -np.linalg.solve(JtJ, Jtr[:, :, None])[:, :, 0]
            norm = np.linalg.norm(delta, axis=1, keepdims=True)
            ab = ab + delta * np.minimum(1.0, 0.6 / np.maximum(norm, 1e-12))
            ab = np.clip(ab, -3.0, 3.0)  # tilts beyond ~72 deg are rejected anyway
        best = ab[0]
        if len(ab) > 1:
            best = ab[int(np.argmin(np.sum(residuals(ab) ** 2, axis=1)))]
        normal = n0 + best[0] * e1 + best[1] * e2
        return normal / np.linalg.norm(normal)

    def _sgbm(
        self,
        left: np.ndarray,
        right: np.ndarray,
        tri: Triangulated,
        blob_l: DiskBlob,
        uv: np.ndarray,
        normal: np.ndarray,
        centroids: np.ndarray,
    ) -> TargetObservation | TargetRejected:
        """Depth from the SGBM map at the left rectified centre; lateral position from it."""
        rect = self.rect
        xy_left = tri.rectified[0]
        radius_px = math.sqrt(blob_l.area / math.pi)
        disparity_offset = rect.cx_left - rect.cx_right  # map disparity minus ours
        sampled = sgbm_disparity_at(
            rect, left, right, xy_left, tri.disparity + disparity_offset, radius_px
        )
        if not isinstance(sampled, SampledDisparity):
            return TargetRejected(sampled)
        d = sampled.disparity - disparity_offset
        if d <= 0:
            return TargetRejected(f"SGBM disparity {d:.1f} px at the target is not positive")
        f, B = rect.focal, rect.baseline
        Z = f * B / d
        x = (xy_left[0] - rect.cx_left) / f
        y = (xy_left[1] - rect.cy) / f
        p = rect.R1.T @ np.array([x * Z, y * Z, Z])
        # covariance: lateral from the left centre's pixel noise, depth from sigma_d
        J = np.array(
            [[Z / f, 0.0, -x * Z / d], [0.0, Z / f, -y * Z / d], [0.0, 0.0, -Z / d]]
        )  # d(X, Y, Z) / d(x_l, y_l, d) in the rectified frame
        cov_in = np.zeros((3, 3))
        cov_in[:2, :2] = blob_l.centroid_cov
        cov_in[2, 2] = sampled.sigma**2
        cov_rect = J @ cov_in @ J.T
        cov = rect.R1.T @ cov_rect @ rect.R1
        return TargetObservation(
            p=p, cov=0.5 * (cov + cov.T), uv=uv, depth_method="sgbm", normal=normal,
            uv_centroid=centroids,
        )
