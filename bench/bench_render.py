"""Benchmark: milliseconds per 1280x1024 stereo pair of the dot target (median of 20).

Run: python bench/bench_render.py
"""

from __future__ import annotations

import statistics
import time

import numpy as np

from controller_stub.geometry import make_transform
from controller_stub.scenario.spec import Scenario
from controller_stub.world.simulation import Simulation


def run(repeats: int = 20) -> dict[str, float]:
    """Render `repeats` target stereo pairs through Simulation.capture_stereo (camera 0.3 m
    from the target, slightly tilted, so the plate covers ~470x470 px) and return timings."""
    sim = Simulation(Scenario())
    sim.capture_stereo("target")  # builds renderers (ray map, noise bank) outside the timing
    left, right = sim.stereo.renderers()
    T_left_target = make_transform([0.01, -0.02, 0.3], [0.1, -0.05, 0.4])
    T_right_left = np.linalg.inv(sim.stereo.T_left_right)
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        left.render_disk(T_left_target, sim.stereo.disk_pattern)
        right.render_disk(T_right_left @ T_left_target, sim.stereo.disk_pattern)
        times.append((time.perf_counter() - t0) * 1e3)
    full = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        sim.capture_stereo("target")
        full.append((time.perf_counter() - t0) * 1e3)
    return {
        "ms_per_stereo_pair_median": statistics.median(times),
        "ms_per_stereo_pair_min": min(times),
        "ms_capture_stereo_out_of_view_median": statistics.median(full),
        "repeats": float(repeats),
    }


if __name__ == "__main__":
    result = run()
    median = result["ms_per_stereo_pair_median"]
    print(f"target stereo pair 1280x1024: {median:.2f} ms (median of 20)")
    for key, value in result.items():
        print(f"  {key}: {value:.3f}")
