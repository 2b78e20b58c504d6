"""Benchmark: fit time for 120 stereo_target poses, zerocal's LM with analytic Jacobians
against a plain scipy least-squares fit with finite differences on the same data, side by side
in one run.

    python bench/bench_fit.py

Cases (all on the same 120-pose UR5e dataset with injected offsets, tool and target errors):
- offsets: joint_offsets only (tool and target known): the issue's 2 ms target;
- offsets+tool+target: the default model (q1, q6 held: not identifiable);
- +geometry: the default model plus every DH delta (many held as unidentifiable).
The scipy baseline solves the same whitened problem with `least_squares(method="lm")` and
its default 2-point finite differences, on the identifiable parameters only (it has no
gauge handling), from the same start. Figures are medians of repeated runs in ms; our fit
is timed without cross-validation (cv_folds=0) and with the default 5 folds.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np
from scipy.optimize import least_squares

from hostpc.fitting import solve
from hostpc.fitting.solver import evaluate
from hostpc.model.problem import build_problem
from hostpc.synthesize import random_truth, synthesize_stereo_target

N_POSES = 120


def _median_ms(func: Callable[[], object], repeats: int) -> float:
    func()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        func()
        times.append(time.perf_counter() - start)
    return 1e3 * float(np.median(times))


def _scipy_baseline(problem, free: np.ndarray) -> Callable[[], np.ndarray]:  # type: ignore[no-untyped-def]
    index = np.flatnonzero(free)

    def residuals(v: np.ndarray) -> np.ndarray:
        x = np.zeros(problem.layout.size)
        x[index] = v
        return evaluate(problem, x, jacobian=False).whitened.ravel()

    def run() -> np.ndarray:
        return least_squares(residuals, np.zeros(index.size), method="lm", xtol=1e-12,
                             ftol=1e-12).x

    return run


def run(repeats: int = 30) -> dict[str, dict[str, float]]:
    truth = random_truth(np.random.default_rng(42))
    offsets = {k: v for k, v in truth.items() if k.startswith("joint_offsets")}
    known = synthesize_stereo_target(offsets, n_samples=N_POSES, seed=42,
                                     known=("tool", "target")).dataset
    free_frames = synthesize_stereo_target(truth, n_samples=N_POSES, seed=42).dataset
    cases = {
        "offsets": (known, None),
        "offsets+tool+target": (free_frames, None),
        "offsets+tool+target+geometry": (free_frames, "+geometry"),
    }
    figures: dict[str, dict[str, float]] = {}
    for name, (dataset, effects) in cases.items():
        problem = build_problem(dataset, effects)
        ours = solve(problem, cv_folds=0)
        baseline = _scipy_baseline(problem, ~ours.fixed)
        v = baseline()
        agreement = float(np.max(np.abs(v - ours.x[~ours.fixed])))
        ours_ms = _median_ms(lambda p=problem: solve(p, cv_folds=0), repeats)
        ours_cv_ms = _median_ms(lambda p=problem: solve(p), max(3, repeats // 5))
        scipy_ms = _median_ms(baseline, max(3, repeats // 5))
        figures[name] = {
            "parameters": float(problem.layout.size),
            "free": float(np.count_nonzero(~ours.fixed)),
            "zerocal_ms": ours_ms,
            "zerocal_with_cv5_ms": ours_cv_ms,
            "scipy_fd_ms": scipy_ms,
            "speedup": scipy_ms / ours_ms,
            "max_parameter_difference": agreement,
        }
    return figures


def main() -> None:
    figures = run()
    print(f"fit of {N_POSES} stereo_target poses (median ms)")
    print(f"{'model':<30} {'P':>3} {'free':>4} {'zerocal':>9} {'+cv5':>8} {'scipy FD':>9} "
          f"{'speedup':>8} {'max |dx|':>9}")
    for name, f in figures.items():
        print(f"{name:<30} {f['parameters']:>3.0f} {f['free']:>4.0f} {f['zerocal_ms']:>9.2f} "
              f"{f['zerocal_with_cv5_ms']:>8.2f} {f['scipy_fd_ms']:>9.2f} {f['speedup']:>7.1f}x "
              f"{f['max_parameter_difference']:>9.1e}")


if __name__ == "__main__":
    main()
