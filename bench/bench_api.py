"""Benchmark: what a user calls, against a plain scipy fit; scaling in N; robot time.

    .venv/bin/python bench/bench_api.py            # 1k, 10k, 100k poses in the scaling table
    .venv/bin/python bench/bench_api.py --quick    # the scaling table stops at 10k

1. The public API against scipy, interleaved in one process (each repeat times ours then
   scipy's, so load on the machine hits both alike), at 120 and 1000 stereo_target poses
   (UR5e, injected offsets, tool and target errors): `hostpc.fit(dataset)` with its
   defaults (5-fold cross-validation on) from a loaded dataset, for the models offsets
   (tool and target known); offsets + tool + target (the default); + geometry. The scipy
   baseline is `least_squares(method="lm")` with 2-point finite differences on the same
   whitened residuals (our `evaluate`, from the same built problem and start), over the
   parameters our fit found identifiable. "same" is the largest difference of the two
   solutions in units of our sigma. Also `hostpc.load_dataset` of the file and
   `hostpc.diagnose(dataset, ladder=True)` (what `hostpc diagnose --ladder` calls).
2. Scaling: per N one subprocess writes the file, a fresh one (the reader's imports
   warmed on a small file) measures: load, fit (defaults), fit with geometry (offsets, all
   DH deltas, tool, target), diagnose (no ladder) of the default model, with the
   process's peak resident memory (`resource.getrusage`, cumulative after each step) and
   CPU seconds.
3. Robot time per method: `hostpc calibrate --robot sim --method M --no-report` as a
   subprocess; robot_time_s from its result.json (simulated clock: motion, 0.3 s settle,
   0.1 s per capture) and the wall time; stereo_target also with --poses 60 (the old
   default). "to sigma": rig + measure, the robot time until the offsets are fitted.
4. Wall time of the default `hostpc calibrate --robot sim` (stereo_target, report
   included), WALL_REPEATS runs one after another (hyperfine-like): wall and CPU seconds
   (user + sys of the host and the simulator processes) per run, median and min.
   `python bench/bench_api.py wall` runs this section alone.

Figures are medians in ms unless stated; put them in docs/performance.md.
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

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from bench.harness import scipy_baseline, stereo_fit_cases, timed  # noqa: E402

SIZES = (120, 1000)
SCALING = (1_000, 10_000, 100_000)
METHODS: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("stereo_target", ()),  # the default: target sigma 0.002 deg, 4 nearby verify poses
    ("stereo_target", ("--poses", "60")),  # the old default: 60 + 10 random
    ("sphere_probe", ()),
    ("dual_loop", ()),
)
WALL_REPEATS = 5
"""Section 4: runs of the default `hostpc calibrate --robot sim` timed one after another."""


def api_versus_scipy(repeats: int = 5) -> list[dict[str, Any]]:
    """Section 1: one row per (N, model)."""
    import hostpc
    from hostpc.dataset import save_dataset
    from hostpc.model.problem import build_problem

    rows = []
    for n_poses in SIZES:
        datasets = stereo_fit_cases(n_poses)
        for case, (dataset, effects) in datasets.items():
            ours = hostpc.fit(dataset, effects)  # warm-up (imports, caches)
            baseline = scipy_baseline(build_problem(dataset, effects), ~ours.fixed)
            x_scipy = baseline()
            ours_s, scipy_s = [], []
            for _ in range(repeats if n_poses <= 200 else max(2, repeats // 2)):
                t, ours = timed(lambda d=dataset, e=effects: hostpc.fit(d, e))
                ours_s.append(t)
                t, x_scipy = timed(baseline)
                scipy_s.append(t)
            free = ~ours.fixed
            same = float(np.max(np.abs(ours.x[free] - x_scipy[free]) / ours.std[free]))
            rows.append({"n": n_poses, "model": case, "parameters": int(ours.x.size),
                         "free": int(np.count_nonzero(free)),
                         "fit_ms": 1e3 * float(np.median(ours_s)),
                         "scipy_ms": 1e3 * float(np.median(scipy_s)),
                         "same_sigma": same})
        dataset = datasets["offsets+tool+target"][0]
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / "dataset.json"
            save_dataset(dataset, path)
            load_s = [timed(lambda p=path: hostpc.load_dataset(p))[0] for _ in range(repeats)]
        hostpc.diagnose(dataset, ladder=True)
        ladder_s = [timed(lambda d=dataset: hostpc.diagnose(d, ladder=True))[0]
                    for _ in range(max(2, repeats // 2))]
        rows.append({"n": n_poses, "model": "load_dataset", "ms": 1e3 * np.median(load_s)})
        rows.append({"n": n_poses, "model": "diagnose --ladder",
                     "ms": 1e3 * np.median(ladder_s)})
    return rows


_SYNTHESIS_CHILD = r"""
import sys
sys.path.insert(0, sys.argv[3])
import numpy as np
from hostpc.dataset import save_dataset
from hostpc.synthesize import random_truth, synthesize_stereo_target
truth = random_truth(np.random.default_rng(42))
save_dataset(synthesize_stereo_target(truth, n_samples=int(sys.argv[1]), seed=42).dataset,
             sys.argv[2])
"""
_SCALING_CHILD = r"""
import json, resource, sys, time
sys.path.insert(0, sys.argv[3])
import hostpc
n, path = int(sys.argv[1]), sys.argv[2]
def peak():
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # MB (Linux: kB)
hostpc.load_dataset(sys.argv[4])  # the reader's imports (pydantic, numpy), not timed
out = {"n": n, "base_mb": peak()}
t, c = time.perf_counter(), time.process_time(); dataset = hostpc.load_dataset(path)
out["load_s"] = time.perf_counter() - t; out["load_cpu_s"] = time.process_time() - c
out["load_peak_mb"] = peak()
print(json.dumps(out), flush=True)
t, c = time.perf_counter(), time.process_time(); json.load(open(path))
out["json_load_s"] = time.perf_counter() - t; out["json_load_cpu_s"] = time.process_time() - c
t, c = time.perf_counter(), time.process_time(); result = hostpc.fit(dataset)
out["fit_s"] = time.perf_counter() - t; out["fit_cpu_s"] = time.process_time() - c
out["fit_peak_mb"] = peak()
print(json.dumps(out), flush=True)
t, c = time.perf_counter(), time.process_time()
hostpc.fit(dataset, effects=["joint_offsets", "geometry", "tool", "target"])
out["geometry_fit_s"] = time.perf_counter() - t
out["geometry_fit_cpu_s"] = time.process_time() - c; out["geometry_peak_mb"] = peak()
print(json.dumps(out), flush=True)
t, c = time.perf_counter(), time.process_time(); hostpc.diagnose(dataset)
out["diagnose_s"] = time.perf_counter() - t; out["diagnose_cpu_s"] = time.process_time() - c
out["diagnose_peak_mb"] = peak()
print(json.dumps(out))
"""


def scaling(sizes: tuple[int, ...] = SCALING, timeout_s: float = 3600.0
            ) -> list[dict[str, Any]]:
    """Section 2: one subprocess per N writes the file (synthesis, not timed), a fresh one
    measures (so its peak memory is the reader's, the fits' and the diagnosis's own)."""
    rows = []
    for n in sizes:
        with tempfile.TemporaryDirectory() as tmp:
            path = str(Path(tmp) / "d.json")
            subprocess.run([sys.executable, "-c", _SYNTHESIS_CHILD, str(n), path, str(ROOT)],
                           check=True, env=_env(), timeout=timeout_s)
            try:
                done = subprocess.run(
                    [sys.executable, "-c", _SCALING_CHILD, str(n), path, str(ROOT),
                     str(ROOT / "examples" / "ur5e_stereo.json")], capture_output=True,
                    text=True, timeout=timeout_s, env=_env(), check=False)
            except subprocess.TimeoutExpired as exc:  # keep the steps that finished
                text = exc.stdout.decode() if isinstance(exc.stdout, bytes) else exc.stdout
                lines = (text or "").strip().splitlines()
                row = json.loads(lines[-1]) if lines else {"n": n}
                rows.append({**row, "error": f"stopped after {timeout_s:.0f} s"})
                continue
        if done.returncode != 0:
            lines = done.stderr.strip().splitlines()
            rows.append({"n": n, "error": lines[-1] if lines else f"exit {done.returncode}"})
        else:
            rows.append(json.loads(done.stdout.strip().splitlines()[-1]))
    return rows


def _env() -> dict[str, str]:
    import os

    env = dict(os.environ)
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    return env


def robot_time(methods: tuple[tuple[str, tuple[str, ...]], ...] = METHODS
               ) -> list[dict[str, Any]]:
    """Section 3: robot time of each method's default simulated calibration."""
    rows = []
    for method, extra in methods:
        with tempfile.TemporaryDirectory() as tmp:
            out = Path(tmp) / "run"
            start = time.perf_counter()
            done = subprocess.run(
                [sys.executable, "-m", "hostpc.cli.main", "calibrate", "--robot", "sim",
                 "--method", method, "--no-report", "--out", str(out), *extra],
                capture_output=True, text=True, cwd=ROOT, env=_env(), check=False)
            wall = time.perf_counter() - start
            result = out / "result.json"
            if not result.is_file():
                lines = done.stderr.strip().splitlines()
                rows.append({"method": " ".join((method, *extra)),
                             "error": lines[-1] if lines else f"exit {done.returncode}"})
                continue
            document = json.loads(result.read_text())
        sigmas = [j.get("sigma_deg") for j in document["offsets"]["joints"]]
        finite = [s for s in sigmas if s is not None]
        rows.append({"method": " ".join((method, *extra)), "wall_s": wall,
                     "n_poses": document["plan"]["n_poses"],
                     "n_verify": document["plan"]["n_verify"],
                     "worst_sigma_deg": max(finite) if finite else None,
                     "exit": document["exit_code"], **document.get("robot_time_s", {})})
    return rows


def wall_time(repeats: int = WALL_REPEATS) -> dict[str, Any]:
    """Section 4: wall and CPU seconds of the default simulated stereo calibration."""
    import resource

    walls, cpus = [], []
    for _ in range(repeats):
        with tempfile.TemporaryDirectory() as tmp:
            before = resource.getrusage(resource.RUSAGE_CHILDREN)
            start = time.perf_counter()
            done = subprocess.run(
                [sys.executable, "-m", "hostpc.cli.main", "calibrate", "--robot", "sim",
                 "--out", str(Path(tmp) / "run")],
                capture_output=True, text=True, cwd=ROOT, env=_env(), check=False)
            walls.append(time.perf_counter() - start)
            after = resource.getrusage(resource.RUSAGE_CHILDREN)
            cpus.append(after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime)
            if done.returncode != 0:
                lines = done.stderr.strip().splitlines()
                return {"error": lines[-1] if lines else f"exit {done.returncode}"}
    return {"runs": repeats, "wall_s": walls, "cpu_s": cpus,
            "wall_median_s": float(np.median(walls)), "wall_min_s": min(walls),
            "cpu_median_s": float(np.median(cpus)), "cpu_min_s": min(cpus)}


def run(quick: bool = False) -> dict[str, Any]:
    sizes = tuple(n for n in SCALING if not quick or n <= 10_000)
    return {"api": api_versus_scipy(), "scaling": scaling(sizes), "robot_time": robot_time(),
            "wall": wall_time()}


def print_tables(figures: dict[str, Any]) -> None:
    print("public API against scipy least_squares (2-point FD), interleaved, median ms")
    print(f"{'N':>5} {'model':<22} {'P':>3} {'free':>4} {'hostpc.fit':>11} {'scipy FD':>9} "
          f"{'ratio':>6} {'same (max |dx|/sigma)':>22}")
    for row in figures["api"]:
        if "fit_ms" in row:
            print(f"{row['n']:>5} {row['model']:<22} {row['parameters']:>3} {row['free']:>4} "
                  f"{row['fit_ms']:>11.1f} {row['scipy_ms']:>9.1f} "
                  f"{row['scipy_ms'] / row['fit_ms']:>5.2f}x {row['same_sigma']:>22.2e}")
        else:
            print(f"{row['n']:>5} {row['model']:<22} {'':>3} {'':>4} {row['ms']:>11.1f}")
    print("\nscaling (defaults; one process per N; geometry: + all DH deltas; peak RSS "
          "cumulative, MB)")
    print(f"{'N':>7} {'load s':>8} {'json s':>7} {'load cpu':>8} {'json cpu':>8} {'fit s':>7} "
          f"{'fit cpu':>8} {'geo cpu':>8} {'diag s':>8} {'diag cpu':>8} {'MB load':>8} "
          f"{'MB fit':>8} {'MB geo':>8} {'MB diag':>8}")
    for row in figures["scaling"]:
        cells = [f"{row[k]:>{w}.{d}f}" if isinstance(row.get(k), float) else f"{'-':>{w}}"
                 for k, w, d in (("load_s", 8, 2), ("json_load_s", 7, 2),
                                 ("load_cpu_s", 8, 2), ("json_load_cpu_s", 8, 2), ("fit_s", 7, 2),
                                 ("fit_cpu_s", 8, 2), ("geometry_fit_cpu_s", 8, 2),
                                 ("diagnose_s", 8, 2), ("diagnose_cpu_s", 8, 2),
                                 ("load_peak_mb", 8, 0), ("fit_peak_mb", 8, 0),
                                 ("geometry_peak_mb", 8, 0), ("diagnose_peak_mb", 8, 0))]
        print(f"{row['n']:>7} " + " ".join(cells)
              + (f"  ({row['error']})" if "error" in row else ""))
    print("\nrobot time of `hostpc calibrate --robot sim` (simulated clock, s)")
    print(f"{'method':<38} {'poses':>6} {'rig':>6} {'measure':>8} {'to sigma':>9} "
          f"{'verify':>7} {'total':>7} {'worst sigma deg':>16} {'wall s':>7}")
    for row in figures["robot_time"]:
        if "error" in row:
            print(f"{row['method']:<38} failed: {row['error']}")
            continue
        sigma = "-" if row["worst_sigma_deg"] is None else f"{row['worst_sigma_deg']:.5f}"
        print(f"{row['method']:<38} {row['n_poses']:>3}+{row['n_verify']:<2} "
              f"{row.get('rig', 0.0):>6.1f} {row.get('measure', 0.0):>8.1f} "
              f"{row.get('rig', 0.0) + row.get('measure', 0.0):>9.1f} "
              f"{row.get('verify', 0.0):>7.1f} {row.get('total', 0.0):>7.1f} {sigma:>16} "
              f"{row['wall_s']:>7.1f}")
    wall = figures.get("wall")
    if wall:
        print("\nwall time of the default `hostpc calibrate --robot sim` (s, one run after "
              "another)")
        if "error" in wall:
            print(f"failed: {wall['error']}")
        else:
            print(f"{wall['runs']} runs: wall median {wall['wall_median_s']:.2f} min "
                  f"{wall['wall_min_s']:.2f}; CPU (host + simulator) median "
                  f"{wall['cpu_median_s']:.2f} min {wall['cpu_min_s']:.2f}; wall "
                  + ", ".join(f"{w:.2f}" for w in wall["wall_s"]))


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    quick = "--quick" in argv
    sections = ([a for a in argv if not a.startswith("--")]
                or ["api", "scaling", "robot", "wall"])
    figures: dict[str, Any] = {"api": [], "scaling": [], "robot_time": []}
    if "api" in sections:
        figures["api"] = api_versus_scipy()
    if "scaling" in sections:
        figures["scaling"] = scaling(tuple(n for n in SCALING if not quick or n <= 10_000))
    if "robot" in sections:
        figures["robot_time"] = robot_time()
    if "wall" in sections:
        figures["wall"] = wall_time()
    print_tables(figures)
    return 0


if __name__ == "__main__":
    sys.exit(main())
