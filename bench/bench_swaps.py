"""Benchmark of any size of motor swap: one joint off by 15 deg (J1..J6, one at a time) and
J2 off by 30 deg, declared with `--swapped`, per method, end to end against the simulated
controller (`hostpc calibrate --robot sim`, the worlds of tests/integration/
test_calibrate_swaps.py: every frame the method needs for all six joints known and true,
the controller's own offset limit raised to 40 deg).

Per case: the verdict, the largest |fitted - true| joint offset (deg), the shifted stages
the run measured (hostpc.calibrate.swaps), the robot time (controller clock, s) and the
wall time. The figures go in docs/performance.md and docs/calibrate.md.

Run: .venv/bin/python bench/bench_swaps.py [--quick] [--methods stereo_target,world_point]
(--quick: J1, J3 and J6 only; `bench/run.py swaps` runs it: it is slow, so optional).
"""

from __future__ import annotations

import argparse
import contextlib
import io
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

OPTIONAL = True
METHODS = ("stereo_target", "world_point", "sphere_probe")


def one(method: str, joint: int, degrees: float, folder: Path) -> dict[str, Any]:
    """One swapped run -> its figures."""
    from hostpc.calibrate.journal import Journal
    from tests.integration.test_calibrate_swaps import calibrate, swap_world

    out = folder / f"{method}-J{joint}-{degrees:g}"
    start = time.perf_counter()
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        try:
            code, document = calibrate(out, swap_world(method, joint, degrees), method,
                                       "--swapped", f"J{joint}")
        except (OSError, ValueError) as exc:  # no result.json: the run stopped early
            return {"method": method, "case": f"J{joint} {degrees:g} deg",
                    "verdict": f"no result ({type(exc).__name__})", "max_error_deg": None,
                    "stages": 0, "robot_time_s": None,
                    "wall_s": time.perf_counter() - start}
    errors = [abs(e) for e in document["truth"]["joint_offsets_error_deg"] if e is not None]
    robot_time = document.get("robot_time_s") or {}
    return {
        "method": method, "case": f"J{joint} {degrees:g} deg",
        "verdict": document["outcome"]["verdict"] + ("" if code == 0 else f" (exit {code})"),
        "max_error_deg": max(errors) if errors else None,
        "stages": len(Journal(out).events("stage")),
        "robot_time_s": robot_time.get("total") if isinstance(robot_time, dict) else robot_time,
        "wall_s": time.perf_counter() - start,
    }


def run(quick: bool = False, methods: tuple[str, ...] = METHODS) -> list[dict[str, Any]]:
    """Every case of every method (module docstring)."""
    joints = (1, 3, 6) if quick else (1, 2, 3, 4, 5, 6)
    rows = []
    with tempfile.TemporaryDirectory(prefix="zerocal-swaps-") as tmp:
        for method in methods:
            cases = [(j, 15.0) for j in joints] + [(2, 30.0)]
            for joint, degrees in cases:
                rows.append(one(method, joint, degrees, Path(tmp)))
                print(_line(rows[-1]), flush=True)
    return rows


def _line(row: dict[str, Any]) -> str:
    error = ("-" if row["max_error_deg"] is None else f"{row['max_error_deg']:.5f}")
    robot = ("-" if row["robot_time_s"] is None else f"{row['robot_time_s']:.1f}")
    return (f"{row['method']:<14} {row['case']:<11} {row['verdict']:<24} max error "
            f"{error:>8} deg  stages {row['stages']}  robot time {robot:>6} s  "
            f"wall {row['wall_s']:.1f} s")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--methods", default=",".join(METHODS))
    args = parser.parse_args(argv)
    run(args.quick, tuple(m for m in args.methods.split(",") if m))
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
