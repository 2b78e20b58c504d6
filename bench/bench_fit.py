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

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the repository root

from bench.harness import median_ms, scipy_baseline, stereo_fit_cases  # noqa: E402
from hostpc.fitting import solve  # noqa: E402
from hostpc.model.problem import build_problem  # noqa: E402

N_POSES = 120
#: the harness's case names as this bench prints them
NAMES = {"offsets": "offsets", "offsets+tool+target": "offsets+tool+target",
         "+geometry": "offsets+tool+target+geometry"}


def run(repeats: int = 30) -> dict[str, dict[str, float]]:
    figures: dict[str, dict[str, float]] = {}
    for case, (dataset, effects) in stereo_fit_cases(N_POSES).items():
        problem = build_problem(dataset, effects)
        ours = solve(problem, cv_folds=0)
        baseline = scipy_baseline(problem, ~ours.fixed)
        x_scipy = baseline()
        agreement = float(np.max(np.abs(x_scipy - ours.x)[~ours.fixed]))
        ours_ms = median_ms(lambda p=problem: solve(p, cv_folds=0), repeats)
        ours_cv_ms = median_ms(lambda p=problem: solve(p), max(3, repeats // 5))
        scipy_ms = median_ms(baseline, max(3, repeats // 5))
        figures[NAMES[case]] = {
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
