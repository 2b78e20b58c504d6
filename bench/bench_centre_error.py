"""Where does the disk centre's error come from? Rendered disks against their known truth.

The simulator's renderer (`controller_stub.sensors.render`) draws the target with a known camera
and pose; `hostpc.vision.target_detection.detect_disk` measures its intensity centroid and
the disk model (`hostpc.vision.triangulation.disk_image_moments`, with the TRUE normal and
the TRUE camera) removes the perspective bias. The error is

    e = (centroid - bias(true centre, true normal)) - projection(true centre)     (px)

and its whitened mean square `e^T cov^-1 e / 2` (per coordinate; `cov` the centroid's
reported covariance) is 1 for an honest covariance. Printed:

1. Noise off (float images): the deterministic error of the renderer's exact pixel-area
   edges, of the one-pixel ramp it used before (the signed distance over the pixel
   footprint, exact only for edges along the grid), and of the same disk rendered 4x and
   8x finer and area-averaged down (a pixel that integrates its area, as a sensor's does).
2. Noise on (a fresh noise field per image, so the draws are independent): by distance,
   tilt and position in the field, and by blur.
3. The normal's share: the error when the bias is computed with a normal off by 0.5 deg
   (what the nominal normal leaves before the stereo_target refinement).
4. The triangulated points of the whole measurement (`TargetMeasurer`, both cameras of the
   simulator with its true rig, true normal as the hint) at robot poses 0.35-0.6 m, tilts
   0-40 deg, against the true centre, whitened along the covariance's principal axes.

    python bench/bench_centre_error.py [--images 60]      (about 2 min; optional in run.py)
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

import controller_stub.sensors.render as render  # noqa: E402
from controller_stub.scenario.spec import CameraSpec, TargetSpec  # noqa: E402
from controller_stub.sensors.render import CameraModel as RenderCamera  # noqa: E402
from controller_stub.sensors.render import DiskPattern, Renderer  # noqa: E402
from hostpc.vision.target_detection import DetectionFailure, detect_disk  # noqa: E402
from hostpc.vision.triangulation import CameraModel, disk_image_moments  # noqa: E402

OPTIONAL = True
"""bench/run.py runs this only when named (`python bench/run.py centre_error`)."""
SPEC = CameraSpec()
TARGET = TargetSpec()
CAMERA = RenderCamera(SPEC.image_width, SPEC.image_height, SPEC.fx, SPEC.fy, SPEC.cx, SPEC.cy,
                      tuple(SPEC.distortion))  # type: ignore[arg-type]
PATTERN = DiskPattern(TARGET.radius, TARGET.plate_radius, TARGET.dot_level, TARGET.plate_level)


def camera_target(tilt: float, azimuth: float, centre: np.ndarray) -> np.ndarray:
    """T_camera_target (4, 4): plate facing the camera, tilted by `tilt` rad about the
    in-plane axis at `azimuth`, disk centre at `centre` (m, camera frame)."""
    axis = np.array([math.cos(azimuth), math.sin(azimuth), 0.0])
    T = np.eye(4)
    T[:3, :3] = cv2.Rodrigues(axis * tilt)[0] @ np.diag([1.0, -1.0, -1.0])
    T[:3, 3] = centre
    return T


def true_centre(camera: RenderCamera, T: np.ndarray, normal_error_deg: float = 0.0,
                rng: np.random.Generator | None = None) -> np.ndarray:
    """(2,) where a perfect measurement lands: projection of the disk centre plus the
    perspective bias of the disk model with the true normal (or one off by
    `normal_error_deg` in a random direction), i.e. the corrected-centroid error is
    measured-centroid minus this."""
    model = CameraModel(camera.K, np.array(camera.distortion), np.eye(3), np.zeros(3))
    centre = T[:3, 3]
    normal = -T[:3, 2] if T[2, 2] > 0 else T[:3, 2]
    disk = disk_image_moments([model], centre[None], normal[None], TARGET.radius)[0]
    if normal_error_deg and rng is not None:
        axis = np.cross(normal, rng.standard_normal(3))
        axis *= math.radians(normal_error_deg) / np.linalg.norm(axis)
        tilted = cv2.Rodrigues(axis)[0] @ normal
        off = disk_image_moments([model], centre[None], tilted[None], TARGET.radius)[0]
        return np.asarray(disk.centre[0] + off.bias[0], float)
    return np.asarray(disk.centroid[0], float)


class _FloatRenderer(Renderer):
    """The renderer without noise and without 8-bit rounding (float32 images)."""

    def _compose(self, patch: np.ndarray | None, box: tuple[int, int, int, int] | None
                 ) -> np.ndarray:
        image = np.full((self.camera.height, self.camera.width), self.background_level,
                        np.float32)
        if patch is not None and box is not None:
            y0, y1, x0, x1 = box
            image[y0:y1, x0:x1] = patch
        return image


def draw_pose(rng: np.random.Generator, distance: float, tilt_deg: float, field: float
              ) -> np.ndarray:
    """A random pose: azimuth, sub-pixel phase and (field > 0) position in the image."""
    x = (rng.uniform(-1, 1) * field * 0.3 + rng.uniform(-0.5, 0.5) / SPEC.fx) * distance
    y = (rng.uniform(-1, 1) * field * 0.25 + rng.uniform(-0.5, 0.5) / SPEC.fy) * distance
    return camera_target(math.radians(tilt_deg), rng.uniform(0, 2 * math.pi),
                         np.array([x, y, distance]))


def noise_free(images: int) -> None:
    """Table 1: deterministic error; one-sample edges against area-integrated pixels."""
    width, height, x0, y0 = 560, 448, 360, 285  # a crop around the optical axis
    cx, cy = SPEC.cx - x0, SPEC.cy - y0
    pattern = DiskPattern(TARGET.radius, 0.04, TARGET.dot_level, TARGET.plate_level)
    crop = RenderCamera(width, height, SPEC.fx, SPEC.fy, cx, cy, CAMERA.distortion)
    rng = np.random.default_rng(5)
    poses = [camera_target(math.radians(rng.uniform(0, 45)), rng.uniform(0, 2 * math.pi),
                           np.array([rng.uniform(-0.02, 0.02), rng.uniform(-0.02, 0.02),
                                     rng.uniform(0.45, 0.7)])) for _ in range(images)]
    truth = [true_centre(crop, T) for T in poses]
    print("1. noise off, blur 0.7 px (float images), 45 tilts 0-45 deg at 0.45-0.7 m:")
    print("   edge rendering                         | RMS error u, v (px)")
    exact_cover = render._pixel_area_cover

    def ramp_cover(signed: np.ndarray, grad_x: np.ndarray, grad_y: np.ndarray) -> np.ndarray:
        return render._smooth_step(signed, np.maximum(np.hypot(grad_x, grad_y), 1e-12))

    for factor, ramp in ((1, False), (1, True), (4, False), (8, False)):
        try:
            render._pixel_area_cover = ramp_cover if ramp else exact_cover  # type: ignore
            fine = RenderCamera(width * factor, height * factor, SPEC.fx * factor,
                                SPEC.fy * factor, factor * (cx + 0.5) - 0.5,
                                factor * (cy + 0.5) - 0.5, CAMERA.distortion)
            renderer = _FloatRenderer(fine, 0.0, 0.0, 120.0, np.random.default_rng(0))
            errors = []
            for T, c in zip(poses, truth, strict=True):
                image = renderer.render_disk(T, pattern)
                if factor > 1:
                    image = cv2.resize(image, (width, height), interpolation=cv2.INTER_AREA)
                image = cv2.GaussianBlur(image, (0, 0), SPEC.blur_sigma)
                blob = detect_disk(image)
                if not isinstance(blob, DetectionFailure):
                    errors.append(blob.centroid - c)
        finally:
            render._pixel_area_cover = exact_cover  # type: ignore
        rms = np.sqrt(np.mean(np.square(errors), axis=0))
        label = ("exact pixel area (the simulator now)" if factor == 1 and not ramp
                 else "one-pixel ramp (the simulator before)" if ramp
                 else f"{factor}x{factor} samples, area-averaged")
        print(f"   {label:<39}| {rms[0]:.4f} {rms[1]:.4f}")


def noisy(images: int, distance: float, tilt_deg: float, field: float, blur: float,
          seed: int, normal_error_deg: float = 0.0) -> tuple[float, float, float, float]:
    """(error std per coordinate, reported sigma, whitened mean square, its standard error)
    over `images` independent noisy renders (a fresh noise field each)."""
    rng = np.random.default_rng(seed)
    errors, reported, whitened = [], [], []
    for k in range(images):
        renderer = Renderer(CAMERA, SPEC.pixel_noise_sigma, blur, TARGET.background_level,
                            np.random.default_rng(seed * 10007 + k))
        T = draw_pose(rng, distance, tilt_deg, field)
        blob = detect_disk(renderer.render_disk(T, PATTERN))
        if isinstance(blob, DetectionFailure):
            continue
        e = blob.centroid - true_centre(CAMERA, T, normal_error_deg, rng)
        errors.append(e)
        reported.append(math.sqrt(0.5 * float(np.trace(blob.centroid_cov))))
        whitened.append(0.5 * float(e @ np.linalg.solve(blob.centroid_cov, e)))
    w = np.asarray(whitened)
    return (float(np.sqrt(np.mean(np.square(errors)))), float(np.mean(reported)),
            float(w.mean()), float(w.std() / math.sqrt(w.size)))


def points(n_poses: int, seed: int = 4) -> None:
    """Table 4: whitened true errors of the measured points (true rig, true normal)."""
    from bench.bench_vision import look_at_q  # noqa: PLC0415 (the simulator's IK helper)
    from controller_stub.scenario.spec import Scenario
    from controller_stub.world.simulation import Simulation
    from hostpc.vision import StereoRig, TargetMeasurer, TargetObservation

    sim = Simulation(Scenario())
    truth = sim.truth()["camera"]
    K = np.array([[truth["fx"], 0, truth["cx"]], [0, truth["fy"], truth["cy"]], [0, 0, 1.0]])
    T_right_left = np.linalg.inv(sim.stereo.T_left_right)
    rig = StereoRig((truth["image_width"], truth["image_height"]), K, truth["distortion"], K,
                    truth["distortion"], T_right_left[:3, :3], T_right_left[:3, 3])
    measurer = TargetMeasurer(rig, TARGET.radius)
    rng = np.random.default_rng(seed)
    whitened = []
    while len(whitened) < n_poses:
        offset = np.array([0.06 + rng.uniform(-0.06, 0.06), rng.uniform(-0.05, 0.05),
                           0.5 + rng.uniform(-0.15, 0.1)])
        q = look_at_q(sim, camera_target(rng.uniform(0.0, 0.7), rng.uniform(0, 2 * math.pi),
                                         offset))
        if q is None:
            continue
        sim.move_joints(q, 1.0)
        frame = sim.capture_stereo("target")
        T = np.linalg.inv(sim.camera_pose()) @ sim.stereo.T_base_target
        normal = T[:3, 2] if T[2, 2] < 0 else -T[:3, 2]
        obs = measurer.measure(frame.left, frame.right, normal_hint=normal)
        if not isinstance(obs, TargetObservation):
            continue
        error = obs.p - T[:3, 3]
        w, V = np.linalg.eigh(obs.cov)
        whitened.append((V.T @ error) ** 2 / w)
    ms = np.asarray(whitened)
    print(f"\n4. measured points, true rig and normal, {n_poses} robot poses: whitened mean "
          f"square per principal axis {ms.mean(axis=0).round(2).tolist()} (small .. depth), "
          f"all {ms.mean():.2f} +- {ms.std() / math.sqrt(ms.size):.2f}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--images", type=int, default=60, help="renders per row")
    args = parser.parse_args(argv)
    n = args.images
    noise_free(max(10, n // 2))
    print(f"\n2. pixel noise {SPEC.pixel_noise_sigma} grey levels, {n} images per row "
          "(whitened mean square: 1 is honest):")
    print("   distance tilt field blur | error RMS  reported | whitened ms")
    rows = [(d, t, f, SPEC.blur_sigma) for d in (0.3, 0.5, 0.7) for t in (0, 30, 45)
            for f in (0.0, 1.0)] + [(0.5, 30, 1.0, 0.0), (0.5, 30, 1.0, 1.5)]
    all_w = []
    for i, (d, t, f, b) in enumerate(rows):
        rms, rep, w, se = noisy(n, d, t, f, b, seed=100 + i)
        all_w.append(w)
        print(f"   {d:.1f} m {t:3.0f} deg {'edge' if f else 'axis'} {b:.1f} px | "
              f"{rms:.4f}   {rep:.4f}  | {w:.2f} +- {se:.2f}")
    print(f"   mean over rows: {np.mean(all_w):.2f}")
    print("\n3. bias computed with a normal off by 0.5 deg (0.5 m, edge of the field):")
    for t in (15, 30, 45):
        rms, rep, w, se = noisy(n, 0.5, t, 1.0, SPEC.blur_sigma, seed=900 + t,
                                normal_error_deg=0.5)
        print(f"   tilt {t:2d} deg | error RMS {rms:.4f}  reported {rep:.4f} | "
              f"whitened ms {w:.2f} +- {se:.2f}")
    points(max(20, 3 * n))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
