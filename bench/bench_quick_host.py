"""Benchmark: the host's own wall time for the two commands a user waits on (issue 28).

- ``hostpc calibrate --robot sim --out DIR`` (the README's main job: simulator start, rig
  calibration, plan, measure, fit, push, verify, report); target <= 3 s on a quiet 2-core
  machine;
- ``hostpc diagnose --ladder DATASET`` at 120 poses (examples/ur5e_stereo_hidden_compliance.json,
  a two-step ladder); target <= 0.3 s.

Each figure is a fresh process as a user starts it (Python start-up and imports included),
median of ``--runs`` (10) runs: its wall time and its CPU time (user + system, with the
simulator's; less sensitive to other processes on the machine than the wall time). With
``--old COMMIT`` the same commands of that commit's tree (``git archive`` of hostpc,
controller_stub and protocol into a temporary folder, first on PYTHONPATH) run interleaved
with the current tree's, one after the other, so both see the same load. Byte code: by
default both trees run once first with byte-code writing on, so every later run imports
``.pyc`` files, as after ``pip install .``; ``--no-byte-code`` runs copies of both trees
without ``.pyc`` files and with PYTHONDONTWRITEBYTECODE=1, as an editable install on the
machine this project is measured on (which sets it): every command then compiles its
~500 modules of the project.

``--instructions`` also counts each command's instructions once per tree under valgrind's
callgrind (the command's own process, not the simulator's; byte code present, the same
folder): unlike the wall and CPU times, the count does not depend on what else runs on the
machine, so it resolves a change of 1 % where ten timed runs on a shared machine do not.

Run: ``python bench/bench_quick_host.py --old HEAD~5 [--runs 10] [--only diagnose]
[--instructions]``
"""

from __future__ import annotations

import argparse
import os
import re
import resource
import shutil
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


def wall_s(source_root: Path, args: list[str], work: Path, byte_code: bool
           ) -> tuple[float, float]:
    """Wall seconds of one ``hostpc ARGS`` with ``source_root`` first on the import path, and
    the CPU seconds (user + system) of it and its children (the simulator): contention from
    other processes stretches the first far more than the second. Run from ``work``
    (``python -m`` puts the working folder first on sys.path)."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    env["PYTHONPATH"] = str(source_root)
    if not byte_code:
        env["PYTHONDONTWRITEBYTECODE"] = "1"
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "hostpc.cli.main", *args], env=env,
                          cwd=work, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                          text=True, timeout=600)
    seconds = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if done.returncode not in (0, 1):  # diagnose of the hidden-compliance example: 1
        raise RuntimeError(f"hostpc {' '.join(args[:2])} failed: {done.stderr.strip()[-300:]}")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return seconds, cpu


def instructions(source_root: Path, args: list[str], work: Path) -> int:
    """Instructions of one ``hostpc ARGS`` (its own process) counted by valgrind's callgrind,
    ``source_root`` first on the import path, run from ``work``, byte code present."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    env["PYTHONPATH"] = str(source_root)
    done = subprocess.run(["valgrind", "--tool=callgrind", "--callgrind-out-file=/dev/null",
                           sys.executable, "-m", "hostpc.cli.main", *args], env=env, cwd=work,
                          stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                          timeout=3600)
    found = re.search(r"Collected : (\d+)", done.stderr)
    if found is None:
        raise RuntimeError(f"callgrind counted nothing: {done.stderr.strip()[-300:]}")
    return int(found.group(1))


Times = dict[str, dict[str, list[tuple[float, float]]]]
"""command -> tree -> (wall s, CPU s) of each counted run."""


def run(runs: int, old_commit: str | None, byte_code: bool = True,
        only: str | None = None, counted: dict[str, dict[str, int]] | None = None) -> Times:
    """The timed runs; with ``counted`` (a dict to fill), each command's instructions per
    tree as well (``instructions``), after the timed runs."""
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        trees = {"now": ROOT}
        if not byte_code:  # the working tree may hold .pyc files of earlier runs
            for package in PACKAGES:
                shutil.copytree(ROOT / package, folder / "now" / package,
                                ignore=shutil.ignore_patterns("__pycache__"))
            trees["now"] = folder / "now"
        if old_commit:
            trees[old_commit] = old_tree(old_commit, folder, PACKAGES)
        commands = {
            "calibrate --robot sim": lambda k: ["calibrate", "--robot", "sim", "--out",
                                                str(folder / f"run-{k}")],
            "diagnose --ladder (120 poses)": lambda k: ["diagnose", "--ladder", "--json",
                                                        str(LADDER_DATASET)],
        }
        if only:
            commands = {c: a for c, a in commands.items() if c.split()[0] == only}
        times: Times = {c: {t: [] for t in trees} for c in commands}
        count = 0
        for _ in range(runs + 1):  # the first round (writes the byte code) is not counted
            for command, arguments in commands.items():
                for tree, root in trees.items():
                    count += 1
                    measured = wall_s(root, arguments(count), folder, byte_code)
                    if count > len(commands) * len(trees):
                        times[command][tree].append(measured)
            print(".", end="", file=sys.stderr, flush=True)
        print(file=sys.stderr)
        if counted is not None:
            for command, arguments in commands.items():
                counted[command] = {tree: instructions(root, arguments(0), folder)
                                    for tree, root in trees.items()}
    return times


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=10)
    parser.add_argument("--old", metavar="COMMIT", help="interleave that commit's tree")
    parser.add_argument("--no-byte-code", action="store_true",
                        help="no .pyc files (an editable install with PYTHONDONTWRITEBYTECODE)")
    parser.add_argument("--only", choices=("calibrate", "diagnose"),
                        help="time only this command")
    parser.add_argument("--instructions", action="store_true",
                        help="also count each command's instructions once per tree (valgrind)")
    args = parser.parse_args()
    load_before = os.getloadavg()[0]
    counted: dict[str, dict[str, int]] | None = {} if args.instructions else None
    times = run(args.runs, args.old, byte_code=not args.no_byte_code, only=args.only,
                counted=counted)
    print("byte code: " + ("none (PYTHONDONTWRITEBYTECODE=1, as an editable install here)"
                           if args.no_byte_code else "written first (as after pip install .)"))
    print(f"load average (1 min) before: {load_before:.2f}, at the end: "
          f"{os.getloadavg()[0]:.2f} (2-core machine: quiet < 0.5)")
    print("| command | tree | wall median s | min s | max s | CPU median s |")
    print("|---|---|---|---|---|---|")
    for command, per_tree in times.items():
        for tree, measured in per_tree.items():
            wall = [w for w, _ in measured]
            cpu = [c for _, c in measured]
            print(f"| {command} | {tree} | {statistics.median(wall):.2f} | {min(wall):.2f} | "
                  f"{max(wall):.2f} | {statistics.median(cpu):.2f} |")
    if counted:
        print()
        print("| command | tree | instructions (callgrind, its own process) |")
        print("|---|---|---|")
        for command, per_tree in counted.items():
            for tree, count in per_tree.items():
                print(f"| {command} | {tree} | {count / 1e9:.3f} G |")

if __name__ == "__main__":
    main()
