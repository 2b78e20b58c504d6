"""Benchmark of `hostpc calibrate`: wall time of the simulated run, and planner efficiency.

1. Wall time of `hostpc calibrate --robot sim` (default scenario, motion time scale 0, rig
   calibrated from chessboard captures, 60 poses, push, 10 verification poses, report).
2. Poses needed to reach a predicted joint-offset standard deviation of 0.002 deg (the
   largest over the identifiable joints), for the planner (greedy D-optimal) and for random
   poses from the same candidate pool (median over draws). Computed from the predicted
   covariance of the model Jacobian with the planning noise model (0.05 px per image
   coordinate): no robot needed. Target: the planner needs at most a third.

Run: python bench/bench_calibrate.py
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

TARGET_SIGMA_DEG = 0.002
RANDOM_DRAWS = 15
MAX_POSES = 400


def wall_time_sim(out_dir: Path) -> dict[str, Any]:
    """Run `hostpc calibrate --robot sim` once; its wall time and headline results."""
    start = time.perf_counter()
    process = subprocess.run(
        [sys.executable, "-m", "hostpc.cli.main", "calibrate", "--robot", "sim",
         "--out", str(out_dir), "--json"],
        capture_output=True, text=True, timeout=600,
    )
    wall = time.perf_counter() - start
    if process.returncode != 0:
        raise RuntimeError(f"hostpc calibrate failed ({process.returncode}): "
                           f"{process.stderr.strip().splitlines()[-1:]}")
    document = json.loads(process.stdout)
    errors = [e for e in document["truth"]["joint_offsets_error_deg"] if e is not None]
    return {
        "sim_wall_time_s": wall,
        "sim_max_abs_offset_error_deg": max(abs(e) for e in errors),
        "sim_verify_rms_after_mm": document["verify"]["rms_after_mm"],
        "sim_verify_passed": document["verify"]["passed"],
    }


def _design(known: tuple[str, ...], n_candidates: int, seed: int) -> Any:
    """The default simulated cell's candidate pool and its design (nominal rig)."""
    from hostpc.kinds.stereo_target.method import StereoTargetMethod
    from hostpc.kinematics import get_robot
    from hostpc.methods.base import RunSettings
    from hostpc.methods.cell import build_cell
    from hostpc.planning.design import design_matrix, make_design
    from hostpc.robots.base import RobotState
    from hostpc.robots.simulator import default_sim_scenario
    from hostpc.vision import StereoRig

    scenario = default_sim_scenario()
    cam, target = scenario["camera"], scenario["target"]
    description = {
        "image_width": cam["image_width"], "image_height": cam["image_height"],
        "baseline_nominal": cam["baseline"], "T_flange_camera_nominal": cam["mount"],
        "target": {"radius": target["radius"], "centre_nominal": target["centre"],
                   "normal": target["normal"]},
    }
    K = np.array([[cam["fx"], 0, cam["cx"]], [0, cam["fy"], cam["cy"]], [0, 0, 1.0]])
    rig = StereoRig(image_size=(cam["image_width"], cam["image_height"]), K_left=K,
                    dist_left=np.zeros(5), K_right=K, dist_right=np.zeros(5), R=np.eye(3),
                    T=np.array([-cam["baseline"], 0.0, 0.0]))
    cell = build_cell(description, scenario["robot"], known=known)
    with tempfile.TemporaryDirectory() as folder:
        method = StereoTargetMethod(
            RunSettings(method="stereo_target", n_candidates=n_candidates), cell, Path(folder))
        method.rig = rig
        chain = get_robot(scenario["robot"])
        home = np.array([0.0, -np.pi / 2, np.pi / 2, -np.pi / 2, -np.pi / 2, 0.0])
        state = RobotState(q=home, zero_offsets=np.zeros(6), q_min=chain.q_min,
                           q_max=chain.q_max)
        pool = method.candidates(state, np.random.default_rng(seed))
        A, names, units = design_matrix(method.design_dataset(pool), None)
    return make_design(A, names, units)


def _worst_sigma_deg(design: Any, indices: np.ndarray) -> float:
    from hostpc.planning.design import joint_offset_sigmas

    sigmas = joint_offset_sigmas(design.subset(indices), 6)
    identifiable = [k for k in range(6) if design.free[design.names.index(
        f"joint_offsets.q{k + 1}")]]
    worst = sigmas[identifiable]
    return float(np.degrees(np.max(worst))) if np.all(np.isfinite(worst)) else float("inf")


def _poses_needed(design: Any, order: np.ndarray) -> int | None:
    """Smallest n such that the first n poses of `order` reach the target sigma."""
    low, high = 1, len(order)
    if _worst_sigma_deg(design, order[:high]) > TARGET_SIGMA_DEG:
        return None
    while low < high:  # the worst sigma only falls as poses are added
        mid = (low + high) // 2
        if _worst_sigma_deg(design, order[:mid]) <= TARGET_SIGMA_DEG:
            high = mid
        else:
            low = mid + 1
    return low


def planner_vs_random(known: tuple[str, ...] = ("target",), n_candidates: int = 1500,
                      seed: int = 0) -> dict[str, Any]:
    """Poses needed for the target sigma: planner vs random poses from the same pool."""
    from hostpc.planning.design import greedy_d_optimal

    design = _design(known, n_candidates, seed)
    n_pool = design.A.shape[0]
    planned = _poses_needed(design, greedy_d_optimal(design, min(MAX_POSES, n_pool)))
    rng = np.random.default_rng(seed + 1)
    draws = [_poses_needed(design, rng.permutation(n_pool)[:MAX_POSES])
             for _ in range(RANDOM_DRAWS)]
    found = [d for d in draws if d is not None]
    random_median = float(np.median(found)) if len(found) == len(draws) else None
    return {
        "known": list(known),
        "target_sigma_deg": TARGET_SIGMA_DEG,
        "n_candidates": n_pool,
        "planner_poses": planned,
        "random_poses_median": random_median,
        "planner_over_random": (planned / random_median
                                if planned and random_median else None),
        "planner_sigma_at_60_deg": _worst_sigma_deg(design, greedy_d_optimal(design, 60)),
    }


def run() -> dict[str, Any]:
    """Both measurements as one flat dict."""
    result: dict[str, Any] = {}
    with tempfile.TemporaryDirectory() as folder:
        result.update(wall_time_sim(Path(folder) / "run"))
    for known, label in ((("target",), "sim_cell"), ((), "frames_estimated")):
        for key, value in planner_vs_random(known).items():
            result[f"{label}.{key}"] = value
    return result


if __name__ == "__main__":
    for key, value in run().items():
        print(f"{key}: {value}")
