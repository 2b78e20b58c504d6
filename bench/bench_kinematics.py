"""Benchmark: forward + screws + point_jacobian for 1000 poses of the UR5e.

Run ``python bench/bench_kinematics.py``; :func:`run` returns the figures as a dict.

Three cases of ``kin_delta``:

- ``nominal``: None (the headline figure);
- ``joint``: per pose ``(N, 5n)`` where only the theta rows differ between poses, with a
  shared geometry delta: what the measurement models pass (joint-space effects + geometry);
- ``per_pose``: every row different per pose (the general, slower path).

Every figure is the median of many repeats of one call, in milliseconds.

Allocator note: the pipeline allocates a few MB of fresh arrays per call. In a process
that has never freed a large block, glibc keeps trimming the heap and every call pays
~1000 page faults (several microseconds each in this VM), which costs more than the
arithmetic. Freeing one large block raises glibc's dynamic mmap/trim thresholds for the
rest of the process; any fit does this on its own (its Jacobians are tens of MB).
:func:`run` therefore measures the nominal pipeline once "cold" (allocator untouched),
then frees one 16 MB block and measures every case "warm".
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from functools import partial
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the repository root

from bench.harness import median_ms  # noqa: E402
from hostpc.kinematics import forward, get_robot, point_jacobian, screws  # noqa: E402

N_POSES = 1000
REPEATS = 300
_WARM_BYTES = 16 * 1024 * 1024
WARM_UP = 10
"""Untimed calls before each timed case."""


def run(n_poses: int = N_POSES, repeats: int = REPEATS) -> dict[str, float]:
    """Median times (ms) for ``n_poses`` UR5e poses.

    Returns:
        ``{"n_poses", "repeats", "cold_nominal_total_ms", "<case>_forward_ms",
        "<case>_screws_ms", "<case>_point_jacobian_ms", "<case>_total_ms"}`` for the cases
        ``nominal``, ``joint`` and ``per_pose``; ``*_total_ms`` times forward + screws +
        point_jacobian as one call (the headline is ``nominal_total_ms``, allocator warm).
    """
    chain = get_robot("ur5e")
    n = chain.n
    rng = np.random.default_rng(0)
    q = rng.uniform(chain.q_min, chain.q_max, size=(n_poses, n))
    joint_delta = np.tile(rng.normal(scale=1e-3, size=5 * n), (n_poses, 1))
    joint_delta[:, :n] += rng.normal(scale=1e-3, size=(n_poses, n))
    cases = {
        "nominal": None,
        "joint": joint_delta,
        "per_pose": rng.normal(scale=1e-3, size=(n_poses, 5 * n)),
    }
    result: dict[str, float] = {"n_poses": float(n_poses), "repeats": float(repeats)}

    def nominal_pipeline() -> None:
        p = forward(chain, q)
        point_jacobian(screws(chain, p), p.T_base_flange[:, :3, 3])

    result["cold_nominal_total_ms"] = median_ms(nominal_pipeline, repeats, WARM_UP)
    block = np.ones(_WARM_BYTES // 8)  # touched, then freed: see the module docstring
    del block
    for case, kin_delta in cases.items():
        poses = forward(chain, q, kin_delta)
        kin_screws = screws(chain, poses)
        x_base = np.ascontiguousarray(poses.T_base_flange[:, :3, 3])

        def pipeline(kin_delta: np.ndarray | None = kin_delta) -> None:
            p = forward(chain, q, kin_delta)
            point_jacobian(screws(chain, p), p.T_base_flange[:, :3, 3])

        stages: dict[str, Callable[[], object]] = {
            "forward": partial(forward, chain, q, kin_delta),
            "screws": partial(screws, chain, poses),
            "point_jacobian": partial(point_jacobian, kin_screws, x_base),
            "total": pipeline,
        }
        for stage, func in stages.items():
            result[f"{case}_{stage}_ms"] = median_ms(func, repeats, WARM_UP)
    return result


if __name__ == "__main__":
    figures = run()
    print(f"ur5e, {int(figures['n_poses'])} poses, median of {int(figures['repeats'])} (ms)")
    print(f"cold allocator, nominal, total: {figures['cold_nominal_total_ms']:.3f}")
    print("warm allocator:")
    print(f"{'kin_delta':10s} {'forward':>9s} {'screws':>9s} {'point_jac':>9s} {'total':>9s}")
    for case in ("nominal", "joint", "per_pose"):
        print(
            f"{case:10s} {figures[f'{case}_forward_ms']:9.3f} {figures[f'{case}_screws_ms']:9.3f}"
            f" {figures[f'{case}_point_jacobian_ms']:9.3f} {figures[f'{case}_total_ms']:9.3f}"
        )
