"""Check: `hostpc diagnose` prints the same as an older commit's, byte for byte (exit codes too).

A speed-up of diagnose must not change what it prints: ``--json`` prints every digit, so
a reordered sum shows. The check runs diagnose of the three examples and four FIGAROH sets
(tests/data: the UR10e as world_pose, the TIAGo's two days and the TALOS arm as world_point
through their URDFs, imported as tests/data/README.md says) with eight option sets each
(56 outputs), with this tree and with ``--old COMMIT``'s (``git archive`` of hostpc, first on
PYTHONPATH), and lists every output that differs. The FIGAROH sets are imported once, by
the old tree, into a temporary folder.

Not a bench (no ``bench_`` prefix: ``bench/run.py`` does not run it); a check to run before a
speed-up of diagnose lands. Run: ``python bench/diagnose_outputs.py --old main [--jobs 2]``
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from bench.harness import old_tree  # noqa: E402

DATA = ROOT / "tests" / "data"
EXAMPLES = ("ur5e_stereo.json", "ur5e_stereo_hidden_compliance.json",
            "ur5e_stereo_known_frames.json")
MARKERS = "marker.a=x1:z1,marker.b=x2:z2,marker.c=x3:z3"
TIAGO = ("--method", "world_point", "--robot", str(DATA / "tiago_arm.urdf"), "--base-link",
         "torso_fixed_link", "--tip-link", "arm_7_link", "--sigma", "0.001")
IMPORTS = {  # name: hostpc import arguments (tests/data/README.md, docs/real-data.md)
    "ur10e": ("figaroh_ur10e_calibration.csv", "--method", "world_pose", "--robot", "ur10e",
              "--columns", "q=shoulder_pan_joint:wrist_3_joint,x=x1,y=y1,z=z1,roll=phix1,"
              "pitch=phiy1,yaw=phiz1", "--sigma", "0.001", "--sigma-angle", "0.0035"),
    "tiago": ("figaroh_tiago_mocap_calibration.csv", *TIAGO, "--columns",
              f"q=torso_lift_joint:arm_7_joint,{MARKERS}"),
    "tiago_day2": ("figaroh_tiago_mocap_2021-11-26.csv", *TIAGO, "--columns",
                   f"q=torso_lift_joint:arm_7_joint,{MARKERS},t=t_start_robot"),
    "talos": ("figaroh_talos_left_arm_mocap.csv", "--method", "world_point", "--robot",
              str(DATA / "talos_left_arm.urdf"), "--base-link", "base_link", "--tip-link",
              "arm_left_7_link", "--sigma", "0.001", "--columns",
              "q=torso_1_joint:arm_left_7_joint,x=x1,y=y1,z=z1,t=t"),
}
OPTION_SETS = ((), ("--ladder",), ("--json",), ("--ladder", "--json"),
               ("--ladder", "--effects", "+joint_compliance"), ("--ladder", "--cv-folds", "0"),
               ("--ladder", "--alpha", "0.01", "--json"),
               ("--candidates", "joint_compliance,encoder_scale", "--json"))


def hostpc(tree: Path, args: list[str], work: Path) -> tuple[int, str, str]:
    """(exit code, stdout, stderr) of ``hostpc ARGS`` with ``tree`` first on the import path,
    run from ``work``."""
    env = {**os.environ, "PYTHONPATH": str(tree)}
    done = subprocess.run([sys.executable, "-m", "hostpc.cli.main", *args], env=env, cwd=work,
                          capture_output=True, text=True, timeout=1800)
    return done.returncode, done.stdout, done.stderr


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--old", metavar="COMMIT", required=True, help="the commit to match")
    parser.add_argument("--jobs", type=int, default=2, help="commands run at once")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        old = old_tree(args.old, folder, ("hostpc",))
        datasets = [ROOT / "examples" / name for name in EXAMPLES]
        for name, (csv, *options) in IMPORTS.items():
            out = folder / f"{name}.json"
            code, _, err = hostpc(old, ["import", str(DATA / csv), *options, "-o", str(out)],
                                  folder)
            if code != 0:
                raise SystemExit(f"import of {csv} failed: {err.strip()[-300:]}")
            datasets.append(out)
        cases = [(dataset, list(options)) for dataset in datasets for options in OPTION_SETS]

        def both(case: tuple[Path, list[str]]) -> bool:
            dataset, options = case
            command = ["diagnose", *options, str(dataset)]
            return hostpc(ROOT, command, folder) == hostpc(old, command, folder)

        with ThreadPoolExecutor(max_workers=max(args.jobs, 1)) as pool:
            same = list(pool.map(both, cases))
    for (dataset, options), equal in zip(cases, same, strict=True):
        if not equal:
            print(f"differs: diagnose {' '.join(options)} {dataset.name}")
    print(f"{sum(same)} of {len(cases)} outputs (stdout, stderr, exit code) equal "
          f"{args.old}'s")
    if not all(same):
        raise SystemExit(1)


if __name__ == "__main__":
    main()
