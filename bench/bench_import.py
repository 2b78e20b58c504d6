"""Benchmark: `hostpc import` of a metrology CSV, wall time and peak memory in N rows.

    /work/venv/bin/python bench/bench_import.py            # N = 10k, 100k, 1M
    /work/venv/bin/python bench/bench_import.py --quick    # N = 10k, 100k
    /work/venv/bin/python bench/bench_import.py --old 1ddeba1   # the previous code alongside

Per case (world_point: a UR5e with two SMR markers, joints in deg and points in mm;
world_pose: a UR10e, SI units, roll/pitch/yaw) and N, a synthetic CSV (forward kinematics of
the built-in robot through a world and a tool/marker frame, 20 um / 0.2 mrad noise, seeded),
then ``python -m hostpc.cli.main import ...`` exactly as a user calls it, each run a fresh
process: wall time (Python's start-up and imports included, about 1 s) and peak resident
memory (``ru_maxrss`` of RUSAGE_CHILDREN in a small wrapper process). With ``--old COMMIT``
the same command runs the importer of that commit too (``git archive`` of its ``hostpc``
into a temporary folder, put first on ``PYTHONPATH``), interleaved with the new one, up to
``OLD_MAX_ROWS`` rows: the old frame guess built every pose pair (N^2/2 Python tuples; 4,600
rows took 1.2 GB), so larger files would exhaust the machine. The guessed frames of the new
importer are checked against the truth (``frame_error_mm``).

Optional in ``bench/run.py`` (OPTIONAL = True: the 1M-row files take minutes): run it by
name, ``bench/run.py import``.
"""

from __future__ import annotations

import argparse
import json
import os
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

from bench.harness import old_tree  # noqa: E402

OPTIONAL = True
SIZES = (10_000, 100_000, 1_000_000)
OLD_SIZES = (1_000, 2_000, 5_000)
OLD_MAX_ROWS = 5_000  # the old importer's memory grows as N^2: 5k rows ~ 1.4 GB
CHUNK = 50_000

#: per case: robot, --columns, extra CLI options
CASES: dict[str, tuple[str, str, tuple[str, ...]]] = {
    "world_point": ("ur5e", "q=J1:J6,x=X,y=Y,z=Z,marker=SMR",
                    ("--joint-unit", "deg", "--length-unit", "mm", "--sigma", "0.02")),
    "world_pose": ("ur10e", "q=q1:q6,x=x,y=y,z=z,roll=roll,pitch=pitch,yaw=yaw", ()),
}
TRUE_WORLD = ([1.8, -0.6, 0.3], [0.05, -0.1, 2.6])
TRUE_TOOL = ([0.02, -0.01, 0.11], [0.3, -0.2, 0.9])
TRUE_MARKERS = {"1": [0.02, 0.0, 0.05], "2": [-0.03, 0.04, 0.06]}


def write_csv(path: Path, method: str, n_rows: int, seed: int = 7) -> None:
    """A synthetic tracker (world_point) or pose (world_pose) export of ``n_rows`` rows,
    written in chunks so that generating 1M rows needs no more memory than 50k."""
    from hostpc.kinematics import forward, get_robot, pose_to_transform

    robot = CASES[method][0]
    chain = get_robot(robot)
    rng = np.random.default_rng(seed)
    W = pose_to_transform(*TRUE_WORLD)
    with path.open("w", encoding="utf-8") as out:
        if method == "world_point":
            out.write("J1,J2,J3,J4,J5,J6,X,Y,Z,SMR\n")
        else:
            out.write("q1,q2,q3,q4,q5,q6,x,y,z,roll,pitch,yaw\n")
        for start in range(0, n_rows, CHUNK):
            n = min(CHUNK, n_rows - start)
            q = rng.uniform(-2.5, 2.5, size=(n, 6))
            T = W @ forward(chain, q).T_base_flange
            if method == "world_point":
                which = (np.arange(start, start + n) % 2)
                marker = np.array(list(TRUE_MARKERS.values()))[which]
                p = np.einsum("nij,nj->ni", T[:, :3, :3], marker) + T[:, :3, 3]
                p += rng.normal(0.0, 2e-5, size=p.shape)
                table = np.column_stack([np.degrees(q), p * 1e3, which + 1])
                np.savetxt(out, table, delimiter=",", fmt=["%.8f"] * 9 + ["%d"])
            else:
                from hostpc.kinematics.rotations import matrix_to_rpy, rotvec_to_matrix

                T = T @ pose_to_transform(*TRUE_TOOL)
                p = T[:, :3, 3] + rng.normal(0.0, 2e-5, size=(n, 3))
                R = T[:, :3, :3] @ rotvec_to_matrix(rng.normal(0.0, 2e-4, size=(n, 3)))
                table = np.column_stack([q, p, matrix_to_rpy(R)])
                np.savetxt(out, table, delimiter=",", fmt="%.10f")


#: run in a fresh, small Python: the command's peak RSS is its RUSAGE_CHILDREN maximum
#: (measured from this bench's process, a forked child would inherit the bench's own
#: high-water mark, which Linux carries across exec)
_PEAK_RSS = ("import resource, subprocess, sys; "
             "code = subprocess.call(sys.argv[1:], stdout=subprocess.DEVNULL); "
             "print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss); sys.exit(code)")


def measure(source_root: Path, csv_path: Path, method: str, output: Path
            ) -> dict[str, float]:
    """Wall seconds and peak RSS (MB) of one ``hostpc import`` in a fresh process."""
    robot, columns, extra = CASES[method]
    env = {**os.environ, "PYTHONPATH": str(source_root)}
    command = [sys.executable, "-m", "hostpc.cli.main", "import", str(csv_path), "--method",
               method, "--robot", robot, "--columns", columns, *extra, "-o", str(output)]
    start = time.perf_counter()
    # run from the CSV's folder: `python -m` puts the working folder first on sys.path,
    # ahead of PYTHONPATH, so from the repository the old tree would never be imported
    run = subprocess.run([sys.executable, "-c", _PEAK_RSS, *command], env=env,
                         cwd=csv_path.parent, capture_output=True, text=True)
    seconds = time.perf_counter() - start
    if run.returncode != 0:
        raise RuntimeError(f"{' '.join(command[2:5])} failed: {run.stderr.strip()}")
    return {"s": seconds, "peak_MB": int(run.stdout.split()[-1]) / 1024.0}


def frame_error(output: Path, method: str) -> float:
    """Largest distance (mm) of the guessed world origin (and tool / marker) from the truth."""
    frames = json.loads(output.read_text())["frames"]
    errors = [np.linalg.norm(np.subtract(frames["world"]["xyz"], TRUE_WORLD[0]))]
    if method == "world_pose":
        errors.append(np.linalg.norm(np.subtract(frames["tool"]["xyz"], TRUE_TOOL[0])))
    else:
        errors += [np.linalg.norm(np.subtract(frames["markers"][name], xyz))
                   for name, xyz in TRUE_MARKERS.items()]
    return 1e3 * float(max(errors))


def run(sizes: tuple[int, ...] = SIZES, old_commit: str | None = None
        ) -> list[dict[str, Any]]:
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        old_root = old_tree(old_commit, folder) if old_commit else None
        all_sizes = sorted(set(sizes) | (set(OLD_SIZES) if old_root else set()))
        for method in CASES:
            for n in all_sizes:
                csv_path = folder / f"{method}-{n}.csv"
                write_csv(csv_path, method, n)
                row: dict[str, Any] = {"case": method, "rows": n,
                                       "csv_MB": csv_path.stat().st_size / 1e6}
                new = measure(ROOT, csv_path, method, folder / "new.json")
                row.update({"new_s": new["s"], "new_peak_MB": new["peak_MB"],
                            "new_us_per_row": 1e6 * new["s"] / n,
                            "frame_error_mm": frame_error(folder / "new.json", method)})
                if old_root is not None and n <= OLD_MAX_ROWS:
                    old = measure(old_root, csv_path, method, folder / "old.json")
                    row.update({"old_s": old["s"], "old_peak_MB": old["peak_MB"]})
                csv_path.unlink()
                rows.append(row)
                print(json.dumps(row), flush=True)
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="10k and 100k rows only")
    parser.add_argument("--old", metavar="COMMIT", help="also run this commit's importer")
    args = parser.parse_args(argv)
    rows = run(SIZES[:2] if args.quick else SIZES, args.old)
    print(f"\n{'case':<12}{'rows':>9}{'csv MB':>8}{'new s':>8}{'us/row':>8}"
          f"{'new peak MB':>13}{'old s':>8}{'old peak MB':>13}{'frame err mm':>14}")
    for row in rows:
        old_s = f"{row['old_s']:.2f}" if "old_s" in row else "-"
        old_mb = f"{row['old_peak_MB']:.0f}" if "old_peak_MB" in row else "-"
        print(f"{row['case']:<12}{row['rows']:>9}{row['csv_MB']:>8.1f}{row['new_s']:>8.2f}"
              f"{row['new_us_per_row']:>8.1f}{row['new_peak_MB']:>13.0f}{old_s:>8}"
              f"{old_mb:>13}{row['frame_error_mm']:>14.4f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
