"""Does the rig cache's check catch a bad cached rig? (issue 28, docs/vision.md's rig cache)

A cached rig is checked against fresh chessboard views before a run uses it
(`hostpc.kinds.stereo_target.rig_cache.check_rig`). The failure the check views are chosen
for is a focal length error both cameras share (a fronto-parallel view hides it). For each
world seed k, the stereo_target world's camera (the simulator's renderer, its chessboard
views; seed k draws the views and the noise), with the camera's true rig (RMS set to a
calibration's 0.03 px: bound 0.075 px):

- the check view a calibration in that world stores (`choose_check_view` over its views
  0..n_views-1; with --station, over the views of the warm-up world first_seed - 1, as a
  station that calibrated the camera once: the bench worlds draw their own board poses);
- each check made on fresh captures with the true rig (it must fit: a miss is a false
  alarm, 20 captures of robot time for nothing) and with each of FAULTS (a fit is a bad rig
  used): both focal lengths x1.01, the left one x1.003 (a changed focus), the left
  principal point 1 px off (a knocked lens), another camera;
- the old check (a cache file without a check view: views 0-3, view 0 and the most tilted
  must fit) and the new one (views 0 and the stored check view, views added while no view
  shows x1.01 above the bound).

    python bench/bench_rig_check.py [--worlds 12] [--first-seed 0] [--station]
    python bench/bench_rig_check.py --target-poses 40   # no chessboard: target_pose_check

Offline (no controller, no robot time): a few seconds a world.
"""

from __future__ import annotations

import argparse
import asyncio
import dataclasses
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
from controller_stub.geometry import rpy_to_matrix  # noqa: E402
from controller_stub.scenario.spec import Scenario  # noqa: E402
from controller_stub.sensors.stereo_target import StereoCamera  # noqa: E402
from hostpc.kinds.stereo_target.rig_cache import (  # noqa: E402
    RigCheck,
    check_rig,
    choose_check_view,
    focal_scaled,
)
from hostpc.robots.simulator import default_sim_scenario  # noqa: E402
from hostpc.vision import ChessboardSpec, StereoRig  # noqa: E402
from hostpc.vision.rig_calibration import find_chessboard  # noqa: E402

CALIBRATION_RMS = 0.03
"""The cached rig's own RMS (px): a calibration's in the simulator (its bound 0.075 px)."""


def true_rig(scenario: dict[str, Any]) -> StereoRig:
    """The scenario's true camera model as a rig (RMS CALIBRATION_RMS)."""
    cam = scenario["camera"]
    K = np.array([[cam["fx"], 0.0, cam["cx"]], [0.0, cam["fy"], cam["cy"]], [0.0, 0.0, 1.0]])
    R_left_right = rpy_to_matrix(np.asarray(cam["right_rpy"], float))
    return StereoRig(image_size=(cam["image_width"], cam["image_height"]), K_left=K,
                     dist_left=np.asarray(cam["distortion"], float), K_right=K,
                     dist_right=np.asarray(cam["distortion"], float), R=R_left_right.T,
                     T=-R_left_right.T @ np.array([cam["baseline"], 0.0, 0.0]),
                     rms=CALIBRATION_RMS)


class World:
    """World `seed`'s camera and chessboard; every capture draws fresh noise."""

    def __init__(self, seed: int) -> None:
        self.scenario = default_sim_scenario(method="stereo_target")
        self.scenario["seed"] = seed
        self.camera = StereoCamera(Scenario.model_validate(self.scenario))
        board = self.scenario["chessboard"]
        self.spec = ChessboardSpec(int(board["cols"]), int(board["rows"]),
                                   float(board["square_size"]))
        self.n_views = int(board["n_views"])

    def corners(self, view: int) -> tuple[Any, Any]:
        left, right = self.camera.render("chessboard", view, lambda: np.eye(4))
        return find_chessboard(left, self.spec), find_chessboard(right, self.spec)

    async def capture(self, view: int) -> tuple[Any, Any]:
        return self.corners(view)

    def check_view(self, rig: StereoRig) -> int:
        """The check view a calibration of this world's views stores."""
        views = [(v, self.corners(v)[0]) for v in range(self.n_views)]
        chosen = choose_check_view(rig, self.spec.object_points(),
                                   [(v, left) for v, left in views if left is not None])
        assert chosen is not None
        return int(chosen["view"])

    def check(self, rig: StereoRig, check_view: int | None) -> RigCheck:
        return asyncio.run(check_rig(rig, self.spec.object_points(), check_view,
                                     self.capture))


def _scaled(rig: StereoRig, left: tuple[float, ...], right: tuple[float, ...]
            ) -> StereoRig:
    """`rig` with K_left, K_right's (fx, fy, cx, cy) multiplied (fx, fy) and shifted (cx,
    cy) by `left`, `right`."""
    def change(K: np.ndarray, d: tuple[float, ...]) -> np.ndarray:
        out = K.copy()
        out[0, 0] *= d[0]
        out[1, 1] *= d[1]
        out[0, 2] += d[2]
        out[1, 2] += d[3]
        return out

    return dataclasses.replace(rig, K_left=change(rig.K_left, left),
                               K_right=change(rig.K_right, right))


FAULTS: dict[str, Callable[[StereoRig], StereoRig]] = {
    "true rig": lambda rig: rig,
    "both focal lengths x1.01": lambda rig: focal_scaled(rig, 1.01),
    "both K x1.01 (principal points too, as the older tests)": lambda rig: dataclasses.replace(
        rig, K_left=np.diag([1.01, 1.01, 1.0]) @ rig.K_left,
        K_right=np.diag([1.01, 1.01, 1.0]) @ rig.K_right),
    "left focal length x1.003 (focus)": lambda rig: _scaled(rig, (1.003, 1.0, 0, 0),
                                                            (1.0, 1.0, 0, 0)),
    "left principal point (+1, +1) px (a knocked lens)": lambda rig: _scaled(
        rig, (1.0, 1.0, 1.0, 1.0), (1.0, 1.0, 0, 0)),
    "another camera (focal lengths x0.99, +-3 px, baseline x1.01)": lambda rig:
        dataclasses.replace(_scaled(rig, (0.99, 0.99, 3.0, -3.0), (0.99, 0.99, -3.0, 3.0)),
                            T=1.01 * rig.T),
}
"""The cached rig of each check, from the camera's true rig: the true rig (it must fit) and
the faults the check must catch."""


def run(worlds: int, first_seed: int, station: bool) -> dict[str, Any]:
    rows = []
    stored = None
    if station:
        warm = World(first_seed - 1)
        stored = warm.check_view(true_rig(warm.scenario))
    for seed in range(first_seed, first_seed + worlds):
        world = World(seed)
        good = true_rig(world.scenario)
        view = stored if station else world.check_view(good)
        row: dict[Any, Any] = {"seed": seed, "check_view": view}
        for fault, make in FAULTS.items():
            for name, check_view in (("old", None), ("new", view)):
                check = world.check(make(good), check_view)
                row[fault, name] = {"views": check.views, "captures": check.captures,
                                    "rms": check.worst, "fits": check.fits,
                                    "bound": check.bound}
        rows.append(row)
        print(f"world {seed}: check view {view}; " + "; ".join(
            f"{name} {fault[:12]} views {row[fault, name]['views']} "
            f"{row[fault, name]['rms']:.3f} px" for fault in FAULTS
            for name in ("old", "new")), file=sys.stderr, flush=True)
    return {"rows": rows, "station_check_view": stored}


def _look_at(T_base_target: np.ndarray, distance: float, tilt_deg: float, azimuth: float
             ) -> np.ndarray:
    """(4, 4) a left camera pose `distance` m from the target centre, its line of sight
    `tilt_deg` off the plate normal (about an in-plane axis at `azimuth`), looking at it."""
    import cv2

    normal, centre = T_base_target[:3, 2], T_base_target[:3, 3]
    axis = T_base_target[:3, 0] * np.cos(azimuth) + T_base_target[:3, 1] * np.sin(azimuth)
    eye = centre + distance * (cv2.Rodrigues(axis * np.radians(tilt_deg))[0] @ normal)
    z = (centre - eye) / np.linalg.norm(centre - eye)
    x = np.cross([0.0, 0.0, 1.0], z)
    x /= np.linalg.norm(x)
    T = np.eye(4)
    T[:3, :3] = np.column_stack([x, np.cross(z, x), z])
    T[:3, 3] = eye - 0.06 * x  # the pair's middle faces the target
    return T


def target_pose_check(poses: int, seed: int = 1) -> dict[str, Any]:
    """The stretch measurement: can one target pose's stereo pair check the rig, with no
    chessboard? The dot's distance from its apparent size (known radius: pi R^2 cos(view
    angle) f^2 / (area cos^3(off-axis angle))) in each camera against the triangulated
    one; per cached rig of FAULTS, the ratio size / stereo - 1 (%) at `poses` random
    look-at poses (0.30-0.55 m, 0-35 deg off the plate normal) of world `seed`, and how many
    poses fall outside the true rig's mean +- 3 sd."""
    from hostpc.vision import TargetMeasurer
    from hostpc.vision.target_detection import DiskBlob, detect_disk

    world = World(seed)
    radius = float(world.scenario["target"]["radius"])
    truth = true_rig(world.scenario)
    T_base_target = world.camera.T_base_target
    rng = np.random.default_rng(seed)
    ratios: dict[str, list[list[float]]] = {fault: [] for fault in FAULTS}
    for _ in range(poses):
        T = _look_at(T_base_target, rng.uniform(0.3, 0.55), rng.uniform(0.0, 35.0),
                     rng.uniform(0.0, 2 * np.pi))
        left, right = world.camera.render("target", 0, T.copy)
        blobs = [detect_disk(image) for image in (left, right)]
        normal = T[:3, :3].T @ T_base_target[:3, 2]  # the plate normal in the left camera,
        normal = normal if normal[2] < 0 else -normal  # towards it
        for fault, make in FAULTS.items():
            rig = make(truth)
            seen = TargetMeasurer(rig, radius).measure(left, right, normal_hint=normal)
            p = getattr(seen, "p", None)
            if p is None:
                continue
            row = []
            for blob, K, point, n in ((blobs[0], rig.K_left, p, normal),
                                      (blobs[1], rig.K_right, rig.R @ p + rig.T,
                                       rig.R @ normal)):
                assert isinstance(blob, DiskBlob)
                r = float(np.linalg.norm(point))
                cos_view, cos_axis = abs(n @ point) / r, point[2] / r
                size = np.sqrt(np.pi * radius**2 * cos_view * K[0, 0] * K[1, 1]
                               / (blob.area * cos_axis**3))
                row.append(100.0 * (size / r - 1.0))
            ratios[fault].append(row)
    true = np.asarray(ratios["true rig"])
    low, high = true.mean(axis=0) - 3 * true.std(axis=0), true.mean(axis=0) + 3 * true.std(axis=0)
    return {fault: {"mean_pct": np.asarray(r).mean(axis=0).round(3).tolist(),
                    "sd_pct": np.asarray(r).std(axis=0).round(3).tolist(),
                    "outside": int(np.any((np.asarray(r) < low) | (np.asarray(r) > high),
                                          axis=1).sum()),
                    "poses": len(r)}
            for fault, r in ratios.items() if r}  # a rig every pose rejects: no figure


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--worlds", type=int, default=12)
    parser.add_argument("--first-seed", type=int, default=0)
    parser.add_argument("--station", action="store_true",
                        help="the check view of the warm-up world first_seed - 1")
    parser.add_argument("--target-poses", type=int, metavar="N",
                        help="instead: the stretch measurement, a rig check from N target "
                        "poses' own images (target_pose_check)")
    args = parser.parse_args(argv)
    if args.target_poses:
        print("| cached rig | size / stereo distance - 1, left, right (%) | sd (%) | poses "
              "outside the true rig's +-3 sd |")
        print("|---|---|---|---|")
        for fault, f in target_pose_check(args.target_poses).items():
            print(f"| {fault} | {f['mean_pct'][0]:+.3f}, {f['mean_pct'][1]:+.3f} | "
                  f"{f['sd_pct'][0]:.3f}, {f['sd_pct'][1]:.3f} | {f['outside']} of "
                  f"{f['poses']} |")
        return 0
    out = run(args.worlds, args.first_seed, args.station)
    rows = out["rows"]
    print("| cached rig | check | worlds | fits | caught | worst view RMS (px) min-max | "
          "bound (px) | captures |")
    print("|---|---|---|---|---|---|---|---|")
    for fault in FAULTS:
        for name in ("old", "new"):
            figures = [r[fault, name] for r in rows]
            counts = ", ".join(f"{c}: {sum(f['captures'] == c for f in figures)}"
                               for c in sorted({f["captures"] for f in figures}))
            rms = [f["rms"] for f in figures]
            print(f"| {fault} | {'4-capture (no check view)' if name == 'old' else '2-capture'}"
                  f" | {len(rows)} | {sum(f['fits'] for f in figures)} | "
                  f"{sum(not f['fits'] for f in figures)} | {min(rms):.3f}-{max(rms):.3f} | "
                  f"{figures[0]['bound']:.3f} | {counts} |")
    if out["station_check_view"] is not None:
        print(f"station: check view {out['station_check_view']} of warm-up world "
              f"{args.first_seed - 1}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
