"""Benchmark of the verification verdict: false-FAIL rate and power (issue 11).

1. False FAIL: `hostpc calibrate --robot sim --method M --seed S` for S = 0..N-1 and M =
   stereo_target, sphere_probe, dual_loop, nothing hidden (the packaged default worlds).
   Every run's pushed offsets are right, so each FAIL (exit 6) is a false alarm. Design
   rate: alpha = 1 % (--verify-alpha); accepted: at most 3 of 100.
2. Power: the stereo_hidden_compliance world (joints 2 and 3 bend under gravity, the
   default model lacks it) with --known target and --force, so the inadequate model's
   offsets are pushed: each must FAIL; accepted: at least 95 of 100.

Run: python bench/bench_verdicts.py [--seeds N] [--methods stereo_target,...]
(100 seeds: about 3 x 100 x 8 s on one core; slow, not part of the test suite.)
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]
METHODS = ("stereo_target", "sphere_probe", "dual_loop")
HIDDEN = REPO / "controller_stub" / "scenarios" / "stereo_hidden_compliance.yaml"


def calibrate(args: list[str], out: Path) -> dict[str, Any]:
    """One `hostpc calibrate` run; its exit code, verdict and verification figures."""
    start = time.perf_counter()
    process = subprocess.run(
        [sys.executable, "-m", "hostpc.cli.main", "calibrate", *args, "--out", str(out),
         "--no-report", "--json"],
        capture_output=True, text=True, timeout=900, cwd=REPO,
    )
    wall = time.perf_counter() - start
    try:
        document = json.loads(process.stdout)
    except ValueError:
        tail = process.stderr.strip().splitlines()[-1:] or [""]
        return {"exit_code": process.returncode, "error": tail[0], "wall_s": wall}
    verify = document.get("verify") or {}
    return {"exit_code": process.returncode, "verdict": verify.get("verdict"),
            "p_value": verify.get("p_value"), "rms_mm": verify.get("rms_mm"),
            "push": document["push"]["status"], "wall_s": wall}


def false_fail(method: str, seeds: int, work: Path, first: int = 0) -> dict[str, Any]:
    runs = [calibrate(["--robot", "sim", "--method", method, "--seed", str(seed)],
                      work / f"{method}-{seed}") for seed in range(first, first + seeds)]
    fails = sum(r.get("verdict") == "FAIL" for r in runs)
    errors = [r for r in runs if r.get("verdict") is None]
    return {"method": method, "runs": seeds, "fails": fails, "no_verdict": len(errors),
            "errors": [r.get("error") for r in errors][:3],
            "wall_s_per_run": sum(r["wall_s"] for r in runs) / max(seeds, 1)}


def power(seeds: int, work: Path, first: int = 0) -> dict[str, Any]:
    runs = [calibrate(["--robot", "sim", "--scenario", str(HIDDEN), "--known", "target",
                       "--force", "--seed", str(seed)], work / f"hidden-{seed}")
            for seed in range(first, first + seeds)]
    fails = sum(r.get("verdict") == "FAIL" for r in runs)
    return {"scenario": HIDDEN.name, "runs": seeds, "fails": fails,
            "pushed": sum(r.get("push") == "pushed" for r in runs),
            "max_p_value": max((r["p_value"] for r in runs if r.get("p_value") is not None),
                               default=None),
            "wall_s_per_run": sum(r["wall_s"] for r in runs) / max(seeds, 1)}


def run(seeds: int = 100, methods: tuple[str, ...] = METHODS, first: int = 0
        ) -> dict[str, Any]:
    with tempfile.TemporaryDirectory(prefix="bench-verdicts-") as tmp:
        work = Path(tmp)
        figures: dict[str, Any] = {"seeds": seeds}
        for method in methods:
            figures[f"false_fail_{method}"] = false_fail(method, seeds, work, first)
        figures["power_hidden_compliance"] = power(seeds, work, first)
    return figures


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=100, help="runs per case (default 100)")
    parser.add_argument("--first-seed", type=int, default=0, help="seed of the first run")
    parser.add_argument("--methods", default=",".join(METHODS),
                        help="comma-separated methods of the false-FAIL study")
    args = parser.parse_args()
    figures = run(args.seeds, tuple(m for m in args.methods.split(",") if m), args.first_seed)
    for key, value in figures.items():
        print(f"{key}: {value}")


if __name__ == "__main__":
    main()
