"""Benchmark: the host's own wall time for the two commands a user waits on (issue 28).

- ``hostpc calibrate --robot sim --out DIR`` (the README's main job: simulator start, rig
  calibration, plan, measure, fit, push, verify, report); target <= 3 s on a quiet 2-core
  machine;
- ``hostpc diagnose --ladder DATASET`` at 120 poses (examples/ur5e_stereo_hidden_compliance.json,
  a two-step ladder); target <= 0.3 s.

Each figure is a fresh process as a user starts it (Python start-up and imports included),
median of ``--runs`` (10) runs. With ``--old COMMIT`` the same commands of that commit's tree
(``git archive`` of hostpc, controller_stub and protocol into a temporary folder, first on
PYTHONPATH) run interleaved with the current tree's, one after the other, so both see the same
load. Byte code: both trees run once first with byte-code writing on, so every later run
imports ``.pyc`` files, as after ``pip install .`` (the machine this project is measured on
sets PYTHONDONTWRITEBYTECODE=1: without ``.pyc`` every command compiles its ~200 modules,
about 0.25 s).

Run: ``python bench/bench_quick_host.py --old HEAD~5 [--runs 10]``
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
LADDER_DATASET = ROOT / "examples" / "ur5e_stereo_hidden_compliance.json"
PACKAGES = ("hostpc", "controller_stub", "protocol")
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from bench.harness import old_tree  # noqa: E402


def wall_s(source_root: Path, args: list[str], work: Path) -> float:
    """Wall seconds of one ``hostpc ARGS`` with ``source_root`` first on the import path.
    Run from ``work`` (``python -m`` puts the working folder first on sys.path)."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    env["PYTHONPATH"] = str(source_root)
    start = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "hostpc.cli.main", *args], env=env,
                          cwd=work, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                          text=True, timeout=600)
    seconds = time.perf_counter() - start
    if done.returncode not in (0, 1):  # diagnose of the hidden-compliance example: 1
        raise RuntimeError(f"hostpc {' '.join(args[:2])} failed: {done.stderr.strip()[-300:]}")
    return seconds


def run(runs: int, old_commit: str | None) -> dict[str, dict[str, list[float]]]:
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        trees = {"now": ROOT}
        if old_commit:
            trees[old_commit] = old_tree(old_commit, folder, PACKAGES)
        commands = {
            "calibrate --robot sim": lambda k: ["calibrate", "--robot", "sim", "--out",
                                                str(folder / f"run-{k}")],
            "diagnose --ladder (120 poses)": lambda k: ["diagnose", "--ladder", "--json",
                                                        str(LADDER_DATASET)],
        }
        times: dict[str, dict[str, list[float]]] = {c: {t: [] for t in trees} for c in commands}
        count = 0
        for _ in range(runs + 1):  # the first round writes the byte code; not counted
            for command, arguments in commands.items():
                for tree, root in trees.items():
                    count += 1
                    seconds = wall_s(root, arguments(count), folder)
                    if count > len(commands) * len(trees):
                        times[command][tree].append(seconds)
            print(".", end="", file=sys.stderr, flush=True)
        print(file=sys.stderr)
    return times


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=10)
    parser.add_argument("--old", metavar="COMMIT", help="interleave that commit's tree")
    args = parser.parse_args()
    times = run(args.runs, args.old)
    print(f"load average at the end: {os.getloadavg()[0]:.2f} (2-core machine: quiet < 0.5)")
    print("| command | tree | median s | min s | max s |")
    print("|---|---|---|---|---|")
    for command, per_tree in times.items():
        for tree, values in per_tree.items():
            print(f"| {command} | {tree} | {statistics.median(values):.2f} | "
                  f"{min(values):.2f} | {max(values):.2f} |")


if __name__ == "__main__":
    main()
