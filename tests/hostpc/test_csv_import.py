"""`hostpc import`: metrology CSV -> dataset document, frame starting values, and one clear
line (row and column) with exit code 2 for every bad CSV."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from hostpc.cli.main import main
from hostpc.importing.frame_guess import guess_world_point, guess_world_pose
from hostpc.kinematics import forward, get_robot, pose_to_transform, rpy_to_matrix
from hostpc.kinematics.rotations import matrix_to_rotvec

DATA = Path(__file__).resolve().parents[1] / "data"
FIGAROH = DATA / "figaroh_ur10e_calibration.csv"
FIGAROH_COLUMNS = ("q=shoulder_pan_joint:wrist_3_joint,x=x1,y=y1,z=z1,"
                   "roll=phix1,pitch=phiy1,yaw=phiz1")


def _run(capsys, *argv):
    code = main(["import", *map(str, argv)])
    out, err = capsys.readouterr()
    return code, out, err


def test_figaroh_ur10e_file_imports_as_world_pose(tmp_path, capsys):
    out = tmp_path / "ur10e.json"
    code, stdout, _ = _run(capsys, FIGAROH, "--method", "world_pose", "--robot", "ur10e",
                           "--columns", FIGAROH_COLUMNS, "-o", out)
    assert code == 0 and "23 samples" in stdout
    doc = json.loads(out.read_text())
    assert doc["method"] == "world_pose" and doc["robot"] == {"name": "ur10e"}
    assert len(doc["samples"]) == 23
    first = doc["samples"][0]
    assert first["q"][0] == pytest.approx(1.589200496673584)
    assert first["p"] == pytest.approx([0.9088284523365023, 0.34156959335807885,
                                        1.2526995668918641])
    assert first["rpy"] == pytest.approx([-1.1869330161318221, -0.5109858420062574,
                                          -2.3796294050596307])
    # the guessed frames explain the real poses to a few mm with the nominal robot
    q = np.array([s["q"] for s in doc["samples"]])
    W = pose_to_transform(doc["frames"]["world"]["xyz"], doc["frames"]["world"]["rpy"])
    X = pose_to_transform(doc["frames"]["tool"]["xyz"], doc["frames"]["tool"]["rpy"])
    predicted = W @ forward(get_robot("ur10e"), q).T_base_flange @ X
    measured = np.array([s["p"] for s in doc["samples"]])
    rms = np.sqrt(np.mean(np.sum((predicted[:, :3, 3] - measured) ** 2, axis=1)))
    assert rms < 0.01


def _world_point_csv(path: Path, header_units: bool = True) -> tuple[np.ndarray, np.ndarray]:
    chain = get_robot("ur5e")
    rng = np.random.default_rng(2)
    q = rng.uniform(-2.0, 2.0, size=(12, 6))
    W = pose_to_transform([1.5, -0.4, 0.2], [0.1, -0.05, 2.5])
    markers = {"A": np.array([0.02, 0.0, 0.05]), "B": np.array([-0.03, 0.04, 0.06])}
    lines = ["J1 (deg),J2 (deg),J3 (deg),J4 (deg),J5 (deg),J6 (deg),X [mm],Y [mm],Z [mm],SMR"
             if header_units else "J1,J2,J3,J4,J5,J6,X,Y,Z,SMR"]
    points = []
    for k, row in enumerate(q):
        name = "AB"[k % 2]
        T = W @ forward(chain, row[None]).T_base_flange[0]
        p = T[:3, :3] @ markers[name] + T[:3, 3]
        points.append(p)
        lines.append(",".join([*(f"{v:.12f}" for v in np.degrees(row)),
                               *(f"{v:.12f}" for v in p * 1e3), name]))
    path.write_text("\n".join(lines) + "\n")
    return q, np.array(points)


def test_world_point_with_markers_and_header_units(tmp_path, capsys):
    csv_path = tmp_path / "tracker.csv"
    q, points = _world_point_csv(csv_path)
    out = tmp_path / "tracker.json"
    code, _, err = _run(capsys, csv_path, "--method", "world_point", "--robot", "ur5e",
                        "--columns", "q=J1:J6,x=X,y=Y,z=Z,marker=SMR", "--sigma", "0.02",
                        "--length-unit", "mm", "-o", out)
    assert code == 0, err
    doc = json.loads(out.read_text())
    np.testing.assert_allclose([s["q"] for s in doc["samples"]], q, atol=1e-12)
    np.testing.assert_allclose([s["p"] for s in doc["samples"]], points, atol=1e-12)
    assert doc["samples"][0]["sigma"] == pytest.approx(2e-5)
    assert [s["marker"] for s in doc["samples"][:2]] == ["A", "B"]
    np.testing.assert_allclose(doc["frames"]["markers"]["A"], [0.02, 0.0, 0.05], atol=1e-9)
    np.testing.assert_allclose(doc["frames"]["markers"]["B"], [-0.03, 0.04, 0.06], atol=1e-9)
    np.testing.assert_allclose(doc["frames"]["world"]["xyz"], [1.5, -0.4, 0.2], atol=1e-9)


@pytest.mark.parametrize("orientation", ["quat", "rotvec"])
def test_quaternion_and_rotation_vector_give_the_same_rpy(tmp_path, capsys, orientation):
    rpy = np.array([0.3, -1.1, 2.9])
    R = rpy_to_matrix(rpy)
    if orientation == "quat":
        from scipy.spatial.transform import Rotation

        x, y, z, w = Rotation.from_matrix(R).as_quat()
        header, values, keys = "qw,qx,qy,qz", [w, x, y, z], "qw=qw,qx=qx,qy=qy,qz=qz"
    else:
        header, values, keys = "rx,ry,rz", list(matrix_to_rotvec(R)), "rx=rx,ry=ry,rz=rz"
    csv_path = tmp_path / "pose.csv"
    csv_path.write_text(f"a,b,c,d,e,f,x,y,z,{header}\n"
                        + ",".join(["0.1"] * 9 + [repr(float(v)) for v in values]) + "\n")
    out = tmp_path / "pose.json"
    code, _, err = _run(capsys, csv_path, "--method", "world_pose", "--robot", "ur5e",
                        "--no-guess", "--columns", f"q=a:f,x=x,y=y,z=z,{keys}", "-o", out)
    assert code == 0, err
    got = json.loads(out.read_text())["samples"][0]["rpy"]
    np.testing.assert_allclose(rpy_to_matrix(got), R, atol=1e-12)


BAD = [
    # (what to break, columns override, expected fragments)
    ("wrong column", "q=J1:J6,x=X,y=Y,z=Zed,marker=SMR", ["row 1", "'Zed'", "z=Zed"]),
    ("text in a number", None, ["row 4", "'J3'", "'abc' is not a number"]),
    ("missing joint", None, ["row 6", "'J5'", "missing value"]),
    ("unknown unit", None, ["row 1", "'Y'", "unknown unit 'furlong'"]),
    ("joint not mapped", "q1=J1,q2=J2,q3=J3,q4=J4,q5=J5,x=X,y=Y,z=Z", ["missing q6"]),
    ("duplicate key", "q=J1:J6,x=X,y=Y,z=Z,x=Y", ["x is given twice", "'x=X'", "'x=Y'"]),
    ("joint twice", "q=J1:J6,q2=J3,x=X,y=Y,z=Z", ["q2 is given twice"]),
    ("reversed range", "q=J6:J1,x=X,y=Y,z=Z", ["q=J6:J1", "reversed", "q=J1:J6"]),
]


@pytest.mark.parametrize(("case", "columns", "fragments"), BAD, ids=[b[0] for b in BAD])
def test_each_bad_csv_is_one_line_and_exit_2(tmp_path, capsys, case, columns, fragments):
    csv_path = tmp_path / "bad.csv"
    _world_point_csv(csv_path)
    lines = csv_path.read_text().splitlines()
    if case == "text in a number":
        cells = lines[3].split(",")
        cells[2] = "abc"
        lines[3] = ",".join(cells)
    elif case == "missing joint":
        cells = lines[5].split(",")
        cells[4] = ""
        lines[5] = ",".join(cells)
    elif case == "unknown unit":
        lines[0] = lines[0].replace("Y [mm]", "Y [furlong]")
    csv_path.write_text("\n".join(lines) + "\n")
    code, out, err = _run(capsys, csv_path, "--method", "world_point", "--robot", "ur5e",
                          "--columns", columns or "q=J1:J6,x=X,y=Y,z=Z,marker=SMR",
                          "-o", tmp_path / "out.json")
    assert code == 2
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err
    for fragment in fragments:
        assert fragment in err, err
    assert not (tmp_path / "out.json").exists()


def test_known_must_name_frames_of_the_method(tmp_path, capsys):
    csv_path = tmp_path / "t.csv"
    _world_point_csv(csv_path)
    args = [csv_path, "--method", "world_point", "--robot", "ur5e",
            "--columns", "q=J1:J6,x=X,y=Y,z=Z,marker=SMR", "-o", tmp_path / "o.json"]
    code, _, err = _run(capsys, *args, "--known", "bogus")
    assert code == 2 and len(err.strip().splitlines()) == 1
    assert "--known: 'bogus' is not a frame of world_point" in err and "world, markers" in err
    assert not (tmp_path / "o.json").exists()
    code, _, err = _run(capsys, *args, "--known", "markers")
    assert code == 0, err
    assert json.loads((tmp_path / "o.json").read_text())["known"] == ["markers"]


def test_bad_options_are_one_line(tmp_path, capsys):
    csv_path = tmp_path / "t.csv"
    _world_point_csv(csv_path)
    code, _, err = _run(capsys, csv_path, "--method", "world_point", "--robot", "ur5e",
                        "--columns", "q=J1:J6,x=X,y=Y,z=Z", "--length-unit", "parsec",
                        "-o", tmp_path / "o.json")
    assert code == 2 and "--length-unit" in err
    code, _, err = _run(capsys, csv_path, "--method", "world_pose", "--robot", "ur5e",
                        "--columns", "q=J1:J6,x=X,y=Y,z=Z", "-o", tmp_path / "o.json")
    assert code == 2 and "needs an orientation" in err


def test_frame_guesses_recover_exact_frames():
    chain = get_robot("ur10e")
    rng = np.random.default_rng(8)
    F = forward(chain, rng.uniform(-2, 2, size=(15, 6))).T_base_flange
    W = pose_to_transform([2.0, 0.5, -0.3], [0.4, -0.2, -2.8])
    X = pose_to_transform([0.05, -0.1, 0.12], [1.2, 0.3, -0.7])
    W_hat, X_hat = guess_world_pose(F, W @ F @ X)
    np.testing.assert_allclose(W_hat, W, atol=1e-9)
    np.testing.assert_allclose(X_hat, X, atol=1e-9)
    marker = np.array([0.03, -0.02, 0.08])
    points = np.einsum("nij,j->ni", (W @ F)[:, :3, :3], marker) + (W @ F)[:, :3, 3]
    W_hat, markers = guess_world_point(F, points)
    np.testing.assert_allclose(W_hat, W, atol=1e-8)
    np.testing.assert_allclose(markers[0], marker, atol=1e-8)


def _figaroh_changed(tmp_path: Path, change) -> Path:  # type: ignore[no-untyped-def]
    """The FIGAROH UR10e file with its lines (header first) changed by ``change``."""
    lines = FIGAROH.read_text().splitlines()
    path = tmp_path / "poses.csv"
    path.write_text("\n".join(change(lines)) + "\n", encoding="utf-8")
    return path


def _with_cell(lines: list[str], line: int, column: int, text: str) -> list[str]:
    cells = lines[line].split(",")
    cells[column] = text
    return [*lines[:line], ",".join(cells), *lines[line + 1:]]


@pytest.mark.parametrize(("cell", "fragment"), [
    ("1_000", "'1_000' is not a plain number (ASCII digits, a sign, '.' and an exponent"),
    ("\u0663", "'\u0663' is not a plain number"),  # an Arabic-Indic three
    ("1e300", "1e+300 rad is outside the physical range (|value| < 100 rad)"),
    ("1000", "1000 rad is outside the physical range (|value| < 100 rad)"),
], ids=["underscore", "arabic-indic-digit", "1e300", "1000-rad"])
def test_a_number_the_fit_would_refuse_is_refused_with_its_row_and_column(
        tmp_path, capsys, cell, fragment):
    """Python's float() reads "1_000" and other scripts' digits, and the dataset's range
    check ran only at `hostpc fit`, naming the sample (samples[5].q[2]), not the CSV's
    row; both are refused at import now, naming row 7 (the file's line) and the column."""
    path = _figaroh_changed(tmp_path, lambda lines: _with_cell(lines, 6, 8, cell))
    code, _, err = _run(capsys, path, "--method", "world_pose", "--robot", "ur10e",
                        "--columns", FIGAROH_COLUMNS, "-o", tmp_path / "out.json")
    assert code == 2, err
    assert err.startswith(f"hostpc import: error: {path}: row 7, column 'elbow_joint': "), err
    assert fragment in err and len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "out.json").exists()


def test_a_length_beyond_the_range_names_its_unit(tmp_path, capsys):
    """The range is the dataset's, in SI: a cell in mm is compared after conversion and
    the line says both."""
    path = _figaroh_changed(tmp_path, lambda lines: _with_cell(lines, 3, 1, "200000"))
    code, _, err = _run(capsys, path, "--method", "world_pose", "--robot", "ur10e",
                        "--columns", FIGAROH_COLUMNS, "--length-unit", "mm",
                        "-o", tmp_path / "out.json")
    assert code == 2
    assert err.strip().endswith("row 4, column 'y1': 200000 (200 m) is outside the "
                                "physical range (|value| < 100 m)"), err


def test_repeated_and_blank_rows_are_read_with_a_warning(tmp_path, capsys):
    """Five rows written again at the end and a blank row inside: imported as they are
    (28 samples; 22), each with one warning line that counts them."""
    path = _figaroh_changed(tmp_path, lambda lines: [*lines, *lines[1:6]])
    code, stdout, err = _run(capsys, path, "--method", "world_pose", "--robot", "ur10e",
                             "--columns", FIGAROH_COLUMNS, "-o", tmp_path / "out.json")
    assert code == 0 and "28 samples" in stdout, err
    assert err.strip().splitlines() == [
        f"warning: {path}: 5 rows repeat an earlier row exactly (row 25 = row 2, row 26 = "
        "row 3, row 27 = row 4, row 28 = row 5, row 29 = row 6): each counts as a "
        "measurement of its own; delete the copies if the pose was not measured again"]
    path = _figaroh_changed(tmp_path, lambda lines: [*lines[:6], "", *lines[7:], "", ""])
    code, stdout, err = _run(capsys, path, "--method", "world_pose", "--robot", "ur10e",
                             "--columns", FIGAROH_COLUMNS, "-o", tmp_path / "out.json")
    assert code == 0 and "22 samples" in stdout, err
    # the blank lines at the end are no pose lost: not counted
    assert err.strip().splitlines() == [
        f"warning: {path}: 1 blank row dropped (row 7); 22 rows read"]


def test_too_few_poses_names_the_file_and_the_next_step(tmp_path, capsys):
    path = _figaroh_changed(tmp_path, lambda lines: lines[:2])
    code, _, err = _run(capsys, path, "--method", "world_pose", "--robot", "ur10e",
                        "--columns", FIGAROH_COLUMNS, "-o", tmp_path / "out.json")
    assert code == 2
    assert err.strip() == (
        f"hostpc import: error: {path}: 1 measurement; world_pose: at least 3 poses are "
        "needed to place the world frame (and a fit of the joint offsets needs many more, "
        "spread over the joints' ranges: docs/metrology.md); measure more poses and import "
        "the file again")
