"""FIT.json at the file edge (hostpc.calibrate.fit_file): what `hostpc fit --json` writes is
read back unchanged, and every damaged field is refused in one line naming it (exit 2)
before the push connects to anything."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from hostpc.calibrate.offline_push import load_saved_fit
from hostpc.cli.main import main

ROOT = Path(__file__).resolve().parents[2]
EXAMPLES = ROOT / "examples"
FIGAROH = ROOT / "tests" / "data" / "figaroh_ur10e_calibration.csv"
COLUMNS = "q=shoulder_pan_joint:wrist_3_joint,x=x1,y=y1,z=z1,roll=phix1,pitch=phiy1,yaw=phiz1"
NO_CONTROLLER = "127.0.0.1:1"  # nothing listens: validation must refuse before connecting


def fit_json(capsys: pytest.CaptureFixture[str], *argv: str) -> str:
    assert main(["fit", *argv, "--cv-folds", "0", "--json"]) == 0
    return capsys.readouterr().out


@pytest.fixture(scope="module")
def example_fit(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    import contextlib
    import io

    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        assert main(["fit", str(EXAMPLES / "ur5e_stereo.json"), "--cv-folds", "0",
                     "--json"]) == 0
    document: dict[str, Any] = json.loads(out.getvalue())
    return document


@pytest.mark.parametrize(("dataset", "options"), [
    ("ur5e_stereo.json", []),
    ("ur5e_stereo_known_frames.json", []),
    ("ur5e_stereo_hidden_compliance.json",
     ["--effects", "joint_offsets,tool,target,joint_compliance"]),
])
def test_what_hostpc_fit_writes_reads_back_unchanged(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], dataset: str,
        options: list[str]) -> None:
    _assert_round_trip(tmp_path, fit_json(capsys, str(EXAMPLES / dataset), *options))


def test_a_world_pose_fit_of_real_data_reads_back_unchanged(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    dataset = tmp_path / "ur10e.json"
    assert main(["import", str(FIGAROH), "--method", "world_pose", "--robot", "ur10e",
                 "--sigma", "0.001", "--sigma-angle", "0.0035", "--columns", COLUMNS,
                 "-o", str(dataset)]) == 0
    capsys.readouterr()
    _assert_round_trip(tmp_path, fit_json(capsys, str(dataset)))


def _assert_round_trip(tmp_path: Path, text: str) -> None:
    document = json.loads(text)
    path = tmp_path / "fit.json"
    path.write_text(text)
    saved = load_saved_fit(path)
    parameters = document["parameters"]
    assert saved.names == tuple(parameters)
    np.testing.assert_array_equal(saved.x, [p["value"] for p in parameters.values()])
    np.testing.assert_array_equal(saved.fixed, [p["fixed"] for p in parameters.values()])
    np.testing.assert_array_equal(
        saved.std, [np.nan if p["std"] is None else p["std"] for p in parameters.values()])
    assert (saved.chi2, saved.dof, saved.converged) == (
        document["chi2"], document["dof"], document["converged"])
    assert saved.chi2_dof_with_calibration == document.get("chi2_dof_with_calibration")
    assert [d.fixed for d in saved.unidentifiable] == [
        d["fixed"] for d in document["unidentifiable"]]


def _set(document: dict[str, Any], path: tuple[str, ...], value: Any) -> None:
    target = document
    for key in path[:-1]:
        target = target[key]
    if value is _DELETE:
        del target[path[-1]]
    else:
        target[path[-1]] = value


_DELETE = object()
Q2 = ("parameters", "joint_offsets.q2")
DAMAGE = [
    (("converged",), "false", "converged: expected true or false (a JSON boolean"),
    ((*Q2, "fixed"), "false", "parameters.joint_offsets.q2.fixed: expected true or false"),
    ((*Q2, "fixed"), _DELETE, "parameters.joint_offsets.q2.fixed: required field missing"),
    ((*Q2, "value"), "0.002", "parameters.joint_offsets.q2.value: expected a finite number"),
    ((*Q2, "value"), 1e300, "parameters.joint_offsets.q2.value: 1e+300 rad is outside"),
    ((*Q2, "value"), 4.0, "parameters.joint_offsets.q2.value: 4 rad is outside"),
    ((*Q2, "std"), -1e-4, "parameters.joint_offsets.q2.std: input should be greater than"),
    (("parameters", "joint_offsets.q1", "std"), 1e-4,
     "parameters.joint_offsets.q1.std: 0.0001 for a fixed parameter"),
    (("chi2",), "144.2", "chi2: expected a finite number (a JSON number, not a string)"),
    (("chi2",), -1.0, "chi2: input should be greater than or equal to 0"),
    (("dof",), 0, "dof: 0, a fit without degrees of freedom cannot be judged"),
    (("dof",), -5, "dof: -5, a fit without degrees of freedom"),
    (("dof",), 167.5, "dof: expected an integer"),
    (("dof",), True, "dof: expected an integer"),
    (("chi2_dof",), 0.5, "chi2_dof: 0.5 is not chi2 / dof"),
    (("chi2_dof_with_calibration",), "1.0", "chi2_dof_with_calibration: expected a finite"),
    (("n_parameters",), 14, "n_parameters: 14 but 15 parameters are listed"),
    (("robot",), 6, "robot: expected a string"),
    (("unidentifiable", 0, "fixed"), "joint_offsets.q2",
     "unidentifiable[0].fixed: 'joint_offsets.q2' is not a fixed parameter"),
    (("unidentifiable", 0, "coefficients"), [1.0],
     "unidentifiable[0].coefficients: 1 coefficients for 3 parameters"),
    (("effects",), ["joint_offsets", "tool"], "parameters.target.x: effect 'target' is not"),
    (("parameters",), {}, "parameters: expected at least one entry"),
    (("parameters",), [], "parameters: expected an object"),
    (("measured_under",), {"run": "/r1", "dataset": "dataset.json", "zero_offsets": ["0"]},
     "measured_under.zero_offsets[0]: expected a finite number"),
    (("measured_under",), {"run": "/r1", "dataset": "dataset.json", "zero_offsets": [7.0]},
     "measured_under.zero_offsets[0]: input should be less than or equal to 3.14"),
    (("measured_under",), {"run": "/r1", "zero_offsets": [0.0]},
     "measured_under.dataset: required field missing"),
]


@pytest.mark.parametrize(("where", "value", "message"), DAMAGE)
def test_a_damaged_fit_file_is_refused_in_one_line_naming_the_field(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], example_fit: dict[str, Any],
        where: tuple[str, ...], value: Any, message: str) -> None:
    document = json.loads(json.dumps(example_fit))
    _set(document, where, value)
    path = tmp_path / "fit.json"
    path.write_text(json.dumps(document))
    _assert_refused(capsys, path, message)


@pytest.mark.parametrize(("edit", "message"), [
    (lambda text: text.replace('"chi2": 1', '"chi2": NaN, "x": 1', 1),
     "NaN is not a number JSON allows"),
    (lambda text: text.replace('"chi2": 1', '"chi2": Infinity, "x": 1', 1),
     "Infinity is not a number JSON allows"),
    (lambda text: text.replace('"converged": true', '"converged": true, "converged": false'),
     "key 'converged' appears twice"),
    (lambda text: text.replace('"dof": 167', '"dof": 1' + "0" * 5000), "not valid JSON"),
    (lambda text: text.replace('"loss": "linear"', '"loss": ' + "[" * 100_000 + "]" * 100_000),
     "not valid JSON (nested too deeply)"),
    (lambda text: text[: len(text) // 2], "not valid JSON (line"),
    (lambda text: "\udcff".join([text[:10], text[10:]]), "not UTF-8 text"),
])
def test_a_damaged_fit_text_is_refused_in_one_line(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], example_fit: dict[str, Any],
        edit: Any, message: str) -> None:
    text = edit(json.dumps(example_fit))
    path = tmp_path / "fit.json"
    path.write_bytes(text.encode("utf-8", "surrogateescape"))
    _assert_refused(capsys, path, message)


def test_joint_offsets_must_match_the_robot_and_be_in_order(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], example_fit: dict[str, Any]
) -> None:
    document = json.loads(json.dumps(example_fit))
    document["parameters"]["joint_offsets.q7"] = {"value": 0.001, "std": 1e-4, "unit": "rad",
                                                  "fixed": False}
    document["n_parameters"] += 1
    path = tmp_path / "fit.json"
    path.write_text(json.dumps(document))
    _assert_refused(capsys, path, "parameters: 7 joint offsets, but a ur5e has 6 joints")
    renamed = {("joint_offsets.q9" if name == "joint_offsets.q3" else name): value
               for name, value in example_fit["parameters"].items()}
    path.write_text(json.dumps({**example_fit, "parameters": renamed, "unidentifiable": []}))
    _assert_refused(capsys, path, "parameters.joint_offsets.q9: the joint offsets must be "
                    "q1..q6 in order")


def _assert_refused(capsys: pytest.CaptureFixture[str], path: Path, message: str) -> None:
    capsys.readouterr()
    assert main(["push", str(path), "--robot", NO_CONTROLLER, "--dry-run"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    assert f"{path}: {message}" in err, err
    assert "hostpc fit" in err  # ends with the command that makes a good one
