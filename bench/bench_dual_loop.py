"""dual_loop: solve-time benchmark and the joint-vs-stepwise Monte-Carlo study.

Data come from the simulated controller's independent humanoid model
(``controller_stub.world.humanoid.HumanoidSimulation``): hostpc plans the poses with its nominal
model, the stub moves there and returns each target triangulated with its covariance.

- :func:`run` (the benchmark): the time to solve one joint dual_loop problem of 2 x 60
  observations (LM only, and the full ``fit`` with 5-fold cross-validation).
- :func:`monte_carlo` (the study, docs/dual-loop.md): per run a new random truth (zero
  errors of all 16 joints, camera, arm bases, targets) and new noise; it compares the joint
  solve (Mahalanobis), the joint solve with identity weights, and the stepwise baseline on
  the error of the camera transform, of the arm-base transforms (each against the truth in
  the fit's gauge) and of predicted target points on held-out poses.

Run ``python bench/bench_dual_loop.py [--runs 50]``.
"""

from __future__ import annotations

import argparse
import json
import time
from collections.abc import Mapping
from typing import Any

import numpy as np

from controller_stub.scenario.spec import scenario_from_dict
from controller_stub.world.humanoid import HumanoidSimulation
from hostpc.dataset import Dataset
from hostpc.fitting import solve
from hostpc.fitting.stepwise import fit_stepwise, gauge_equivalent, identity_weighted
from hostpc.kinds.dual_loop.planning import PlannedPoses, plan_poses
from hostpc.kinds.dual_loop.synthesize import make_dataset
from hostpc.kinematics.rotations import matrix_to_rotvec, pose_to_transform, rotvec_to_matrix
from hostpc.model.layout import Problem
from hostpc.model.measurements.predict import predict
from hostpc.model.problem import build_problem

POSE_FRAMES = ("camera", "left_base", "right_base")


def random_scenario(seed: int, pixel_sigma: float = 0.15) -> dict[str, Any]:
    """A humanoid scenario with a random hidden truth drawn from `seed`: zero errors
    +-0.5 deg, camera +-2 mm / +-0.3 deg, arm bases +-3 mm / +-0.3 deg, targets +-1 mm."""
    rng = np.random.default_rng([seed, 77])
    deg = np.pi / 180

    def pose(mm: float, degrees: float) -> dict[str, list[float]]:
        return {"xyz": (rng.uniform(-mm, mm, 3) * 1e-3).tolist(),
                "rpy": (rng.uniform(-degrees, degrees, 3) * deg).tolist()}

    return {
        "seed": int(seed),
        "robot": "humanoid_upper",
        "truth": {"zero_errors": {"random_deg": 0.5}},
        "humanoid": {
            "camera_error": pose(2.0, 0.3),
            "left_base_error": pose(3.0, 0.3),
            "right_base_error": pose(3.0, 0.3),
            "left_target_error": (rng.uniform(-1, 1, 3) * 1e-3).tolist(),
            "right_target_error": (rng.uniform(-1, 1, 3) * 1e-3).tolist(),
            "pixel_sigma": pixel_sigma,
        },
    }


def acquire(sim: HumanoidSimulation, poses: PlannedPoses) -> tuple[Dataset, np.ndarray]:
    """Visit the poses on the stub and measure the planned arm's target at each.

    Returns the dataset (nominal frames) and the indices of the poses kept (a target the
    true geometry puts outside the images is skipped)."""
    p, cov, kept = [], [], []
    for i in range(poses.n):
        q = sim.joint_positions()
        side = str(poses.chain[i])
        q[0:2] = poses.q_head[i]
        span = slice(2, 9) if side == "left" else slice(9, 16)
        q[span] = poses.q_arm[i]
        sim.move_joints(q, 1.0)
        seen = sim.targets.measure_targets()["targets"].get(side)
        if seen is None:
            continue
        p.append(seen["p"])
        cov.append(seen["cov"])
        kept.append(i)
    index = np.asarray(kept, dtype=int)
    return make_dataset(poses.subset(index), np.array(p), np.array(cov)), index


def truth_vector(truth: Mapping[str, Any], problem: Problem,
                 zero_errors: str = "zero_errors") -> np.ndarray:
    """The stub's truth (``sim.truth()``) as hostpc parameters on ``problem``'s layout:
    offsets = the zero errors under key `zero_errors` (``zero_errors_initial``: against the
    offsets at the start of a run that has since pushed); pose deltas ``t_true - t_nom``,
    ``log(R_nom^T R_true)``; point deltas ``p_true - p_nom``."""
    values: dict[str, float] = {}
    for label, error in zip(truth["joint_order"], truth[zero_errors], strict=True):
        values[f"joint_offsets.{label}"] = float(error)
    frames = problem.dataset.frames
    for name in POSE_FRAMES:
        nominal = frames[name]
        T_nom = pose_to_transform(nominal.xyz, nominal.rpy)  # type: ignore[union-attr]
        T_true = pose_to_transform(truth[name]["xyz"], truth[name]["rpy"])
        dt = T_true[:3, 3] - T_nom[:3, 3]
        r = matrix_to_rotvec(T_nom[:3, :3].T @ T_true[:3, :3])
        for k, axis in enumerate("xyz"):
            values[f"{name}.{axis}"] = float(dt[k])
            values[f"{name}.r{axis}"] = float(r[k])
    for side in ("left", "right"):
        delta = np.asarray(truth[f"{side}_target"]) - np.asarray(frames[f"{side}_target"])
        for k, axis in enumerate("xyz"):
            values[f"{side}_target.{axis}"] = float(delta[k])
    return np.array([values.get(name, 0.0) for name in problem.layout.names])


def pose_error(problem: Problem, x: np.ndarray, x_ref: np.ndarray, name: str
               ) -> tuple[float, float]:
    """Translation (m) and rotation (rad) error of pose frame ``name`` between two
    parameter vectors (both deltas from the same nominal)."""
    span = problem.layout.effect_slices[name]
    d, d_ref = x[span], x_ref[span]
    R = rotvec_to_matrix(d[3:6])
    R_ref = rotvec_to_matrix(d_ref[3:6])
    angle = float(np.linalg.norm(matrix_to_rotvec(R_ref.T @ R)))
    return float(np.linalg.norm(d[:3] - d_ref[:3])), angle


def heldout_rms(problem: Problem, x: np.ndarray, heldout: Dataset, truth_p: np.ndarray
                ) -> float:
    """RMS (m) over held-out poses of |predicted - true| target points in the camera."""
    held = build_problem(heldout, [t.effect.name for t in problem.terms])
    predicted, _ = predict(held, x, jacobian=False)
    return float(np.sqrt(np.mean(np.sum((predicted - truth_p) ** 2, axis=1))))


def true_points(sim: HumanoidSimulation, poses: PlannedPoses) -> np.ndarray:
    """(N, 3) noise-free target points in the camera frame at the poses (stub truth)."""
    out = np.empty((poses.n, 3))
    for i in range(poses.n):
        q = sim.joint_positions()
        side = str(poses.chain[i])
        q[0:2] = poses.q_head[i]
        q[slice(2, 9) if side == "left" else slice(9, 16)] = poses.q_arm[i]
        sim.move_joints(q, 1.0)
        out[i] = sim.target_in_camera(side)
    return out


def run_once(seed: int, n_per_arm: int = 60, n_heldout: int = 20,
             pixel_sigma: float = 0.15) -> dict[str, dict[str, float]]:
    """One Monte-Carlo run: errors of the joint, joint-unweighted and stepwise solves.

    Returns ``{solver: {"camera_mm", "camera_deg", "bases_mm", "bases_deg",
    "heldout_mm"}}``; camera and base errors against the truth in the fit's gauge."""
    sim = HumanoidSimulation(scenario_from_dict(random_scenario(seed, pixel_sigma)))
    rng = np.random.default_rng([seed, 5])
    dataset, _ = acquire(sim, plan_poses(n_per_arm, rng))
    heldout_poses = plan_poses(n_heldout // 2, rng)
    truth_p = true_points(sim, heldout_poses)
    heldout = make_dataset(heldout_poses, truth_p,
                           np.broadcast_to(np.eye(3) * 1e-8, (heldout_poses.n, 3, 3)))
    problem = build_problem(dataset)
    joint = solve(problem, cv_folds=0)
    unweighted = solve(identity_weighted(problem), cv_folds=0)
    stepwise = fit_stepwise(dataset)
    x_truth = truth_vector(sim.truth(), problem)
    x_ref = gauge_equivalent(problem, x_truth, joint.fixed)
    out: dict[str, dict[str, float]] = {}
    for label, x in (("joint", joint.x), ("joint_unweighted", unweighted.x),
                     ("stepwise", stepwise.x)):
        cam_t, cam_r = pose_error(problem, x, x_ref, "camera")
        bases = [pose_error(problem, x, x_ref, f"{s}_base") for s in ("left", "right")]
        out[label] = {
            "camera_mm": cam_t * 1e3,
            "camera_deg": np.degrees(cam_r),
            "bases_mm": float(np.mean([b[0] for b in bases])) * 1e3,
            "bases_deg": float(np.degrees(np.mean([b[1] for b in bases]))),
            "heldout_mm": heldout_rms(problem, x, heldout, truth_p) * 1e3,
        }
    return out


def monte_carlo(n_runs: int = 50, first_seed: int = 1000, n_per_arm: int = 60
                ) -> dict[str, Any]:
    """The study: :func:`run_once` for ``n_runs`` seeds; mean and RMS of every metric per
    solver, and how often the joint solve's camera error is <= the stepwise one."""
    runs = [run_once(first_seed + k, n_per_arm) for k in range(n_runs)]
    table: dict[str, dict[str, dict[str, float]]] = {}
    for solver in runs[0]:
        table[solver] = {}
        for metric in runs[0][solver]:
            values = np.array([r[solver][metric] for r in runs])
            table[solver][metric] = {"mean": float(values.mean()),
                                     "rms": float(np.sqrt(np.mean(values**2))),
                                     "p90": float(np.percentile(values, 90))}
    wins = [r["joint"]["camera_mm"] <= r["stepwise"]["camera_mm"] for r in runs]
    return {"runs": n_runs, "n_per_arm": n_per_arm, "table": table,
            "joint_camera_wins": float(np.mean(wins))}


def markdown_table(study: Mapping[str, Any]) -> str:
    """The study as the markdown table of docs/dual-loop.md (RMS over runs)."""
    rows = ["| solver | camera (mm) | camera (deg) | arm bases (mm) | arm bases (deg) | "
            "held-out points (mm) |", "|---|---|---|---|---|---|"]
    for solver, metrics in study["table"].items():
        cells = [f"{metrics[m]['rms']:.3f}" for m in
                 ("camera_mm", "camera_deg", "bases_mm", "bases_deg", "heldout_mm")]
        rows.append(f"| {solver} | " + " | ".join(cells) + " |")
    return "\n".join(rows)


def run(n_per_arm: int = 60, repeats: int = 5) -> dict[str, float]:
    """Benchmark: median solve time (s) of one joint dual_loop problem, 2 x n_per_arm."""
    sim = HumanoidSimulation(scenario_from_dict(random_scenario(1)))
    dataset, _ = acquire(sim, plan_poses(n_per_arm, np.random.default_rng(1)))
    problem = build_problem(dataset)
    lm, full, build = [], [], []
    for _ in range(repeats):
        t0 = time.perf_counter()
        problem = build_problem(dataset)
        t1 = time.perf_counter()
        result = solve(problem, cv_folds=0)
        t2 = time.perf_counter()
        solve(problem)
        t3 = time.perf_counter()
        build.append(t1 - t0)
        lm.append(t2 - t1)
        full.append(t3 - t2)
    return {
        "observations": float(dataset.n_samples),
        "parameters": float(problem.layout.size),
        "iterations": float(result.iterations),
        "build_problem_s": float(np.median(build)),
        "solve_s": float(np.median(lm)),
        "solve_with_cv5_s": float(np.median(full)),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=0, help="also run the Monte-Carlo study")
    args = parser.parse_args()
    print(json.dumps(run(), indent=2))
    if args.runs:
        study = monte_carlo(args.runs)
        print(json.dumps(study, indent=2))
        print(markdown_table(study))


if __name__ == "__main__":
    main()
