"""Benchmark of the cell-reference check: is a moved frame detected and named, and how often
does a clean cell raise a false alarm?

Per simulated world (seed w) and method: a RECORDING dataset (small zero errors, J1 and J6
exact: the zeros are good) is fitted with every frame estimated and turned into a reference
(hostpc.calibrate.reference.reference_from_fit); then a RUN dataset of the same cell after a
motor swap (J1 and J6 +2 deg, fresh small errors elsewhere, new poses and noise) is fitted
with the reference as priors and checked (hostpc.calibrate.reference_check). Cases:

- clean: nothing moved (a flagged frame is a false alarm);
- target moved 0.5 mm (stereo_target), sphere moved 0.5 mm (sphere_probe), reflector nest
  moved 0.5 mm (world_point), camera remounted 0.2 deg (stereo_target): detected when the
  check names that frame as the likely cause.

The move's direction is random but perpendicular to the one direction no data can see (the
target's or sphere's turn about base z is joint 1, the camera's or nest's turn about the
flange axis is joint 6: a move along it IS a joint error to every measurement, and is
reported as such in docs/calibrate.md). Datasets are synthesized offline with hostpc's own
model (hostpc.synthesize for stereo_target; the measurement models' example poses for the
others: 4 x 6 sphere_probe orientations, the method's >= 20, with every contact solved
onto the true sphere) instead of running the simulator: 40 worlds
x 5 cases take seconds, not hours, on a shared 2-core machine. The stub-based end-to-end
runs are the integration tests (tests/integration/test_calibrate_reference.py).

Run: python bench/bench_reference.py [--worlds 40] [--quick]
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from hostpc.calibrate.reference import frame_priors, reference_from_fit  # noqa: E402
from hostpc.calibrate.reference_check import check_reference  # noqa: E402
from hostpc.dataset import Dataset, Samples  # noqa: E402
from hostpc.fitting import fit  # noqa: E402
from hostpc.fitting.priors import with_prior_blocks  # noqa: E402
from hostpc.kinds.sphere_probe.file_face import reference_sphere, stylus_radius
from hostpc.model.measurements.predict import predict  # noqa: E402
from hostpc.model.problem import build_problem  # noqa: E402

SWAP = math.radians(2.0)
STEREO_NOISE = 0.25
"""hostpc.synthesize's stereo noise scaled to the simulated camera's (12 um lateral, 60 um
in depth at 0.5 m: the stub's stated noise RMS is about 24 um per point)."""
CASES = (("stereo_target", "clean", None), ("stereo_target", "target", "target"),
         ("stereo_target", "camera", "tool"), ("sphere_probe", "clean", None),
         ("sphere_probe", "sphere", "sphere"), ("world_point", "clean", None),
         ("world_point", "nest", "markers"))


def _small_offsets(rng: np.random.Generator, good_1_6: bool) -> dict[str, float]:
    truth = {f"joint_offsets.q{j}": math.radians(rng.uniform(-0.1, 0.1)) for j in range(1, 7)}
    if good_1_6:
        truth["joint_offsets.q1"] = truth["joint_offsets.q6"] = 0.0
    return truth


def _frame_errors(method: str, rng: np.random.Generator) -> dict[str, float]:
    """The cell's real frames (errors from nominal), fixed per world."""
    errors: dict[str, float] = {}
    if method == "stereo_target":
        for axis in "xyz":
            errors[f"tool.{axis}"] = rng.uniform(-1e-3, 1e-3)
            errors[f"tool.r{axis}"] = math.radians(rng.uniform(-0.3, 0.3))
            errors[f"target.{axis}"] = rng.uniform(-1e-3, 1e-3)
    elif method == "sphere_probe":
        for axis in "xyz":
            errors[f"tool.{axis}"] = rng.uniform(-5e-4, 5e-4)
            errors[f"sphere.{axis}"] = rng.uniform(-5e-4, 5e-4)
    else:
        for axis in "xyz":
            errors[f"world.{axis}"] = rng.uniform(-1e-3, 1e-3)
            errors[f"world.r{axis}"] = math.radians(rng.uniform(-0.1, 0.1))
            for marker in ("a", "b"):
                errors[f"markers.{marker}.{axis}"] = rng.uniform(-3e-4, 3e-4)
    return errors


def _perpendicular(rng: np.random.Generator, unseen: np.ndarray) -> np.ndarray:
    """A random unit 3-vector perpendicular to `unseen` (3,)."""
    v = rng.standard_normal(3)
    u = unseen / np.linalg.norm(unseen)
    v -= (v @ u) * u
    return v / np.linalg.norm(v)


def _move(method: str, frame: str, dataset: Dataset, truth: dict[str, float],
          rng: np.random.Generator) -> dict[str, float]:
    """The truth with `frame` moved 0.5 mm (a point) or turned 0.2 deg (the camera)."""
    moved = dict(truth)
    z = np.array([0.0, 0.0, 1.0])
    if frame in ("target", "sphere"):  # the unseen direction: a turn about base z
        centre = (np.asarray(dataset.frames["target"], float) if frame == "target"
                  else np.asarray(reference_sphere(dataset).center, float))
        step = 5e-4 * _perpendicular(rng, np.cross(z, centre))
        for k, axis in enumerate("xyz"):
            moved[f"{frame}.{axis}"] += float(step[k])
    elif frame == "markers":  # nest a: unseen is its turn about the flange axis
        nest = np.asarray(dataset.frames["markers"]["a"], float)
        step = 5e-4 * _perpendicular(rng, np.cross(z, nest))
        for k, axis in enumerate("xyz"):
            moved[f"markers.a.{axis}"] += float(step[k])
    else:  # the camera: turned 0.2 deg about an axis perpendicular to the flange axis
        pose = dataset.pose("tool")
        from hostpc.kinematics.rotations import rpy_to_matrix

        axis_in_tool = np.asarray(rpy_to_matrix(pose.rpy), float).T @ _perpendicular(rng, z)
        for k, name in enumerate(("rx", "ry", "rz")):
            moved[f"tool.{name}"] += math.radians(0.2) * float(axis_in_tool[k])
    return moved


def _stereo(truth: dict[str, float], seed: int) -> Dataset:
    from hostpc.synthesize import synthesize_stereo_target

    return synthesize_stereo_target(truth, n_samples=20, seed=seed,
                                    noise_scale=STEREO_NOISE).dataset


def _points(template: Dataset, truth: dict[str, float], rng: np.random.Generator) -> Dataset:
    """world_point: the template's poses measured with `truth` plus the tracker's noise."""
    problem = build_problem(template, list(dict.fromkeys(n.split(".", 1)[0] for n in truth)))
    x = np.array([truth.get(n, 0.0) for n in problem.layout.names])
    clean, _ = predict(problem, x, jacobian=False)
    cov = np.broadcast_to(np.eye(3) * (10e-6) ** 2, clean.shape + (3,)).copy()
    noisy = clean + 10e-6 * rng.standard_normal(clean.shape)
    samples = dataclasses.replace(template.samples, p=noisy, cov=cov)
    return template.with_samples(samples)


def _contacts(template: Dataset, truth: dict[str, float], rng: np.random.Generator) -> Dataset:
    """sphere_probe: each pose moved along its distance gradient until the true tip touches
    the true sphere (distance = R + r + noise), as a latched contact would be."""
    effects = list(dict.fromkeys(n.split(".", 1)[0] for n in truth))
    rho = float(reference_sphere(template).radius) + float(stylus_radius(template) or 0.0)
    sigma = np.asarray(template.samples.sigma, float)
    target = rho + sigma * rng.standard_normal(sigma.size)
    q = np.asarray(template.samples.q, float).copy()

    def distance(q_now: np.ndarray) -> np.ndarray:
        data = template.with_samples(dataclasses.replace(template.samples, q=q_now))
        problem = build_problem(data, effects)
        x = np.array([truth.get(n, 0.0) for n in problem.layout.names])
        return predict(problem, x, jacobian=False)[0][:, 0]

    for _ in range(30):  # Newton along the distance gradient, steps capped at 0.1 rad
        base = distance(q)
        miss = base - target
        if np.max(np.abs(miss)) < 1e-12:
            break
        gradient = np.zeros_like(q)
        for j in range(q.shape[1]):
            bumped = q.copy()
            bumped[:, j] += 1e-7
            gradient[:, j] = (distance(bumped) - base) / 1e-7
        step = gradient * (miss / np.sum(gradient**2, axis=1))[:, None]
        q -= step * np.minimum(1.0, 0.1 / np.maximum(np.max(np.abs(step), axis=1), 1e-300))[:, None]
    return template.with_samples(dataclasses.replace(template.samples, q=q))


def _dataset(method: str, truth: dict[str, float], seed: int) -> Dataset:
    rng = np.random.default_rng(seed)
    if method == "stereo_target":
        return _stereo(truth, seed)
    from hostpc.model.measurements.registry import measurement_models

    template = measurement_models()[method].example(rng)
    if method == "world_point":
        return _points(template, truth, rng)
    parts = [template] + [measurement_models()[method].example(rng) for _ in range(3)]
    samples = Samples(  # 24 probe orientations, as the method's >= 20 (S6)
        q=np.concatenate([d.samples.q for d in parts]),
        sigma=np.concatenate([d.samples.sigma for d in parts]),
        group=np.concatenate([d.samples.group + 100 * k for k, d in enumerate(parts)]),
        speed=np.concatenate([d.samples.speed for d in parts]),
        approach=np.concatenate([d.samples.approach for d in parts]))
    return _contacts(template.with_samples(samples), truth, rng)


def one_case(method: str, frame: str | None, world: int) -> dict[str, Any]:
    """Record on world `world`, swap J1 and J6, optionally move `frame`, fit and check."""
    rng = np.random.default_rng(1000 + world)
    frames = _frame_errors(method, rng)
    record_truth = {**_small_offsets(rng, True), **frames}
    recording = fit(_dataset(method, record_truth, 2 * world), cv_folds=0)
    reference = reference_from_fit(recording, robot_serial="bench", cell={},
                                   source_run="bench", software="bench")
    run_truth = {**_small_offsets(rng, False), **frames}
    run_truth["joint_offsets.q1"] += SWAP
    run_truth["joint_offsets.q6"] += SWAP
    template = _dataset(method, run_truth, 2 * world + 1)
    if frame is not None:
        run_truth = _move(method, frame, template, run_truth, rng)
    dataset = _dataset(method, run_truth, 2 * world + 1)
    priors = frame_priors(reference, dataset, build_problem(dataset).frame_names)
    result = fit(with_prior_blocks(dataset, [p.block() for p in priors]), cv_folds=0)
    check = check_reference(result, priors)
    errors = [math.degrees(result.value(f"joint_offsets.q{j}")
                           - run_truth[f"joint_offsets.q{j}"]) for j in range(1, 7)]
    return {"cause": check.likely_cause, "max_error_deg": max(abs(e) for e in errors)}


def run(worlds: int = 40) -> dict[str, Any]:
    figures: dict[str, Any] = {}
    for method, case, frame in CASES:
        start = time.perf_counter()
        outcomes = [one_case(method, frame, w) for w in range(worlds)]
        if frame is None:
            hits = sum(o["cause"] is not None for o in outcomes)
            label = "false alarms"
        else:
            hits = sum(o["cause"] == frame for o in outcomes)
            label = "detected and named"
        worst = max(o["max_error_deg"] for o in outcomes)
        figures[f"{method} {case}"] = {
            label: f"{hits}/{worlds}",
            "largest J error (deg)": round(worst, 4) if frame is None else "-",
            "s": round(time.perf_counter() - start, 1)}
    return figures


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--worlds", type=int, default=40)
    parser.add_argument("--quick", action="store_true", help="10 worlds")
    args = parser.parse_args(argv if argv is not None else sys.argv[1:])
    figures = run(10 if args.quick else args.worlds)
    for name, row in figures.items():
        print(f"{name:<28}" + "  ".join(f"{k}: {v}" for k, v in row.items()))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
