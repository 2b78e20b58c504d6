"""FIGAROH's own held-out error on zerocal's pose-grouped folds (docs/real-data.md).

Two steps in two environments (FIGAROH needs pinocchio, which zerocal does not):

1. With zerocal's venv, write which CSV rows each of the 5 folds of
   `hostpc.fitting.folds.fold_indices` holds, for the three real sets of tests/data:

       python bench/figaroh_held_out.py folds -o folds.json

2. With a separate venv (`pip install pin figaroh==0.7.0`; the FIGAROH examples of
   repository thanhndv212/figaroh-examples, commit c0b5c7f, unpacked in EXAMPLES, need that
   version), train FIGAROH's own calibration class of each example (its cost, its
   parameters, its outlier rejection) on four folds and predict the fifth with FIGAROH's
   `calc_updated_fkm`:

       python bench/figaroh_held_out.py figaroh --examples EXAMPLES --folds folds.json

   It prints the held-out position RMS (and orientation RMS for the UR10e's full poses) over
   all samples. The examples' URDFs name mesh files the snapshot does not hold; the script
   loads copies without visual and collision elements (the kinematics is unchanged).
"""

from __future__ import annotations

import argparse
import contextlib
import csv
import io
import json
import sys
import tempfile
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "tests" / "data"

#: name -> (CSV, zerocal import arguments, FIGAROH example dir, class, URDF, config)
SETS: dict[str, tuple[str, list[str], str, str, str, str]] = {
    "ur10e": ("figaroh_ur10e_calibration.csv",
              ["--method", "world_pose", "--robot", "ur10e", "--sigma", "0.001",
               "--sigma-angle", "0.0035", "--columns",
               "q=shoulder_pan_joint:wrist_3_joint,x=x1,y=y1,z=z1,roll=phix1,pitch=phiy1,"
               "yaw=phiz1"],
              "ur10", "examples.ur10.utils.ur10_tools.UR10Calibration",
              "urdf/ur10_robot.urdf", "config/ur10_config_new.yaml"),
    "tiago": ("figaroh_tiago_mocap_calibration.csv",
              ["--method", "world_point", "--robot", str(DATA / "tiago_arm.urdf"),
               "--base-link", "torso_fixed_link", "--tip-link", "arm_7_link", "--sigma",
               "0.001", "--columns",
               "q=torso_lift_joint:arm_7_joint,marker.a=x1:z1,marker.b=x2:z2,marker.c=x3:z3"],
              "tiago", "examples.tiago.utils.tiago_tools.TiagoCalibration",
              "urdf/tiago.urdf", "config/tiago_config.yaml"),
    "talos": ("figaroh_talos_left_arm_mocap.csv",
              ["--method", "world_point", "--robot", str(DATA / "talos_left_arm.urdf"),
               "--base-link", "base_link", "--tip-link", "arm_left_7_link", "--sigma", "0.001",
               "--columns", "q=torso_1_joint:arm_left_7_joint,x=x1,y=y1,z=z1,t=t"],
              "talos", "examples.talos.utils.talos_tools.TALOSCalibration",
              "urdf/talos_full_v2.urdf", "config/talos_config.yaml"),
}


def write_folds(out: Path) -> None:
    import hostpc
    from hostpc.cli.main import main
    from hostpc.fitting.folds import fold_indices

    folds: dict[str, list[list[int]]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for name, (csv_name, arguments, *_) in SETS.items():
            dataset = Path(tmp) / f"{name}.json"
            assert main(["import", str(DATA / csv_name), *arguments, "-o", str(dataset)]) == 0
            samples = hostpc.load_dataset(dataset).samples
            q = np.asarray(samples.q, float)
            with open(DATA / csv_name, newline="") as handle:
                rows = np.array(list(csv.reader(handle))[1:], float)
            joints = rows[:, -q.shape[1]:]  # the joints are the last columns of each file
            row_of = [int(np.flatnonzero(np.all(joints == qs, axis=1))[0]) for qs in q]
            indices = fold_indices(samples, 5)
            assert indices is not None
            folds[name] = [sorted({row_of[i] for i in fold}) for fold in indices]
    out.write_text(json.dumps(folds))
    print(f"wrote {out}: " + ", ".join(f"{k} {[len(f) for f in v]}" for k, v in folds.items()))


def _without_meshes(urdf: Path, directory: Path) -> Path:
    tree = ET.parse(urdf)
    for link in tree.getroot().findall("link"):
        for tag in ("visual", "collision"):
            for element in link.findall(tag):
                link.remove(element)
    out = directory / urdf.name
    tree.write(out)
    return out


def figaroh_held_out(examples: Path, folds_file: Path, markers: dict[str, int]) -> None:
    import os

    from figaroh.calibration.calibration_tools import calc_updated_fkm
    from figaroh.tools.robot import load_robot

    sys.path.insert(0, str(examples.parent))
    folds = json.loads(folds_file.read_text())
    for name, (_, _, directory, class_path, urdf, config) in SETS.items():
        module, class_name = class_path.rsplit(".", 1)
        calibration_class = getattr(__import__(module, fromlist=[class_name]), class_name)
        os.chdir(examples / directory)
        with tempfile.TemporaryDirectory() as tmp:
            plain = _without_meshes(Path(urdf).resolve(), Path(tmp))
            config_path = Path(config)
            if markers.get(name, 1) > 1:  # the examples' configs name one marker
                text = yaml_with_markers(config_path.read_text(), markers[name])
                config_path = Path(tmp) / "config.yaml"
                config_path.write_text(text)
            position, angle = _cross_validate(calibration_class, load_robot, calc_updated_fkm,
                                              plain, config_path, folds[name])
        line = f"{name}: FIGAROH held-out position RMS {position * 1e3:.3f} mm"
        if angle is not None:
            line += f", orientation RMS {np.degrees(angle):.3f} deg"
        print(line)


def yaml_with_markers(text: str, count: int) -> str:
    """The TIAGo config with its commented-out second and third markers restored."""
    commented = ("    # - ref_joint: arm_7_joint\n"
                 "    #   measure: [True, True, True, False, False, False]\n")
    restored = ("    - ref_joint: arm_7_joint\n"
                "      measure: [True, True, True, False, False, False]\n")
    assert text.count(commented) >= count - 1
    return text.replace(commented, restored, count - 1)


def _cross_validate(calibration_class: Any, load_robot: Any, calc_updated_fkm: Any,
                    urdf: Path, config: Path, folds: list[list[int]]
                    ) -> tuple[float, float | None]:
    rows = sum(len(fold) for fold in folds)

    def calibration(deleted: list[int]) -> Any:
        robot = load_robot(str(urdf), load_by_urdf=True)
        made = calibration_class(robot=robot, config_file=str(config), del_list=deleted)
        made.calib_config["known_baseframe"] = False
        made.calib_config["known_tipframe"] = False
        return made

    position: list[float] = []
    angle: list[float] = []
    for test in folds:
        train = calibration(test)
        with contextlib.redirect_stdout(io.StringIO()):
            train.initialize()
            train.solve(plotting=False, enable_logging=False)
        held = calibration(sorted(set(range(rows)) - set(test)))
        with contextlib.redirect_stdout(io.StringIO()):
            held.load_data_set()
        config_held = dict(train.calib_config)
        config_held["NbSample"] = len(test)
        predicted = calc_updated_fkm(train.model, train.data, train.LM_result.x,
                                     held.q_measured, config_held)
        error = (held.PEE_measured - predicted).reshape(-1, len(test))  # rows: x1, y1, ...
        per_marker = int(sum(train.calib_config["measurability"]))
        for block in np.split(error, error.shape[0] // per_marker):
            position.extend(np.sum(block[:3] ** 2, axis=0))
            if per_marker == 6:  # roll, pitch, yaw differences: small angles
                angle.extend(np.sum(block[3:] ** 2, axis=0))
    return (float(np.sqrt(np.mean(position))),
            float(np.sqrt(np.mean(angle))) if angle else None)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="step", required=True)
    folds = sub.add_parser("folds")
    folds.add_argument("-o", "--output", type=Path, default=Path("folds.json"))
    run = sub.add_parser("figaroh")
    run.add_argument("--examples", type=Path, required=True,
                     help="the examples/ directory of figaroh-examples")
    run.add_argument("--folds", type=Path, default=Path("folds.json"))
    run.add_argument("--tiago-markers", type=int, default=3,
                     help="markers of the TIAGo file FIGAROH reads (its example reads 1)")
    args = parser.parse_args()
    if args.step == "folds":
        write_folds(args.output)
    else:
        figaroh_held_out(args.examples.resolve(), args.folds.resolve(),
                         {"tiago": args.tiago_markers})


if __name__ == "__main__":
    main()
