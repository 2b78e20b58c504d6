"""`hostpc fit DATASET --robot FILE.urdf --base-link L --tip-link L`: fit with another robot
than the one the dataset names; bad overrides are one line, exit 2."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from hostpc.cli.main import main
from hostpc.dataset.reading import dataset_from_dict
from hostpc.model.measurements.predict import predict
from hostpc.model.problem import build_problem
from tests.hostpc.test_urdf_fit import URDF, _document, _poses

WRONG_ROBOT = {"convention": "dh", "joints": [
    {"a": 0.1 * k, "alpha": 0.5, "d": 0.1, "theta": 0.0} for k in range(7)]}


def _dataset_file(tmp_path: Path) -> Path:
    q = _poses(40)
    problem = build_problem(dataset_from_dict(_document(q, np.zeros((len(q), 3))),
                                              base_dir=URDF.parent), "joint_offsets")
    x = np.radians([0.0, 0.2, -0.1, 0.3, -0.2, 0.1, 0.25])
    x[0] = 0.002  # the lift: m
    y, _ = predict(problem, x, jacobian=False)
    document = _document(q, y, robot=WRONG_ROBOT)  # a file that names the wrong robot
    path = tmp_path / "arm.json"
    path.write_text(json.dumps(document))
    return path


def test_robot_override_fits_the_urdf_chain(tmp_path, capsys):
    path = _dataset_file(tmp_path)
    assert main(["fit", str(path), "--json", "--cv-folds", "0"]) == 0
    wrong = json.loads(capsys.readouterr().out)
    assert main(["fit", str(path), "--json", "--cv-folds", "0", "--robot", str(URDF),
                 "--base-link", "base_link", "--tip-link", "tool0"]) == 0
    right = json.loads(capsys.readouterr().out)
    assert right["rms"] < 1e-10 < wrong["rms"]
    assert abs(right["parameters"]["joint_offsets.q1"]["value"] - 0.002) < 1e-9


def test_bad_robot_override_is_one_line(tmp_path, capsys):
    path = _dataset_file(tmp_path)
    for argv, message in (
        (["--robot", "ur5e"], "--robot has 6 joints, the samples 7"),
        (["--robot", str(URDF)], "needs --base-link and --tip-link"),
        (["--base-link", "base_link"], "only with --robot"),
        (["--robot", str(URDF), "--base-link", "base_link", "--tip-link", "nope"], "'nope'"),
    ):
        assert main(["fit", str(path), *argv]) == 2
        err = capsys.readouterr().err
        assert message in err and len(err.strip().splitlines()) == 1, err
