"""`hostpc import` reads what metrology software writes: several reflectors in one row,
decimal commas, Euler angle sequences, temperature and per-axis sigma columns. Each CSV is
written from a known truth (forward kinematics, scipy's Euler angles), imported, loaded back
with the dataset reader and compared exactly; each malformed value is one line and exit 2."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from hostpc.cli.main import main
from hostpc.dataset.reading import load_dataset
from hostpc.kinematics import forward, get_robot, pose_to_transform, rpy_to_matrix

WORLD = pose_to_transform([1.5, -0.4, 0.2], [0.1, -0.05, 2.5])
MARKERS = {"a": np.array([0.02, 0.0, 0.05]), "b": np.array([-0.03, 0.04, 0.06]),
           "c": np.array([0.0, -0.05, 0.04])}


def _run(capsys, *argv):
    code = main(["import", *map(str, argv)])
    out, err = capsys.readouterr()
    return code, out, err


def _one_line_exit_2(code: int, err: str, *fragments: str) -> None:
    assert code == 2, err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err, err
    for fragment in fragments:
        assert fragment in err, err


def _tracker_truth(n: int = 8) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Joint values (rad) and each reflector's world point (m) at them."""
    q = np.random.default_rng(4).uniform(-2.0, 2.0, size=(n, 6))
    T = WORLD @ forward(get_robot("ur5e"), q).T_base_flange
    return q, {name: np.einsum("nij,j->ni", T[:, :3, :3], m) + T[:, :3, 3]
               for name, m in MARKERS.items()}


def _three_reflector_csv(path: Path, lost: tuple[int, str] | None = None,
                         separator: str = ",", decimal: str = ".") -> tuple[np.ndarray, dict]:
    q, points = _tracker_truth()
    header = ["J1", "J2", "J3", "J4", "J5", "J6",
              *(f"{axis}{k}" for k in (1, 2, 3) for axis in "xyz")]
    lines = [separator.join(header)]
    for i, row in enumerate(q):
        cells = [repr(float(v)) for v in row]
        for name in "abc":
            seen = lost != (i, name)
            cells += [repr(float(v)) if seen else "" for v in points[name][i]]
        lines.append(separator.join(c.replace(".", decimal) for c in cells))
    path.write_text("\n".join(lines) + "\n")
    return q, points


REFLECTORS = "q=J1:J6,marker.a=x1:z1,marker.b=x2:z2,marker.c=x3:z3"


def test_several_reflectors_in_one_row_give_one_sample_each(tmp_path, capsys):
    csv_path, out = tmp_path / "three.csv", tmp_path / "three.json"
    q, points = _three_reflector_csv(csv_path, lost=(3, "b"))
    code, stdout, err = _run(capsys, csv_path, "--method", "world_point", "--robot", "ur5e",
                             "--columns", REFLECTORS, "-o", out)
    assert code == 0, err
    assert "23 samples" in stdout  # 8 rows x 3 reflectors, b lost in one
    samples = json.loads(out.read_text())["samples"]
    expected = [(i, name) for i in range(len(q)) for name in "abc" if (i, name) != (3, "b")]
    assert [s["marker"] for s in samples] == [name for _, name in expected]
    np.testing.assert_array_equal([s["q"] for s in samples], [q[i] for i, _ in expected])
    np.testing.assert_array_equal([s["p"] for s in samples],
                                  [points[name][i] for i, name in expected])
    dataset = load_dataset(out)
    assert list(dataset.frames["markers"]) == ["a", "b", "c"]
    for name, marker in MARKERS.items():  # the frame guess finds every reflector
        np.testing.assert_allclose(dataset.frames["markers"][name], marker, atol=1e-8)


@pytest.mark.parametrize(("columns", "fragments"), [
    ("q=J1:J6,marker.a=x1:y1", ["marker.a=x1:y1 spans 2 columns"]),
    ("q=J1:J6,marker.a=x1:z1,x=x2", ["drop x="]),
    ("q=J1:J6,marker.a=x1:z1,sigma.b=x2", ["sigma.b= names no reflector"]),
    ("q=J1:J6,marker.a=z1:x1", ["reversed", "marker.a=x1:z1"]),
])
def test_bad_reflector_groups_are_one_line(tmp_path, capsys, columns, fragments):
    csv_path = tmp_path / "three.csv"
    _three_reflector_csv(csv_path)
    code, _, err = _run(capsys, csv_path, "--method", "world_point", "--robot", "ur5e",
                        "--columns", columns, "-o", tmp_path / "o.json")
    _one_line_exit_2(code, err, *fragments)


@pytest.mark.parametrize("decimal", ["auto", ","])
def test_decimal_commas_read_exactly_as_points(tmp_path, capsys, decimal):
    dot_csv, comma_csv = tmp_path / "dot.csv", tmp_path / "comma.csv"
    _three_reflector_csv(dot_csv)
    _three_reflector_csv(comma_csv, separator=";", decimal=",")
    assert "," in comma_csv.read_text().splitlines()[1]
    args = ["--method", "world_point", "--robot", "ur5e", "--columns", REFLECTORS, "--no-guess"]
    assert _run(capsys, dot_csv, *args, "-o", tmp_path / "dot.json")[0] == 0
    code, _, err = _run(capsys, comma_csv, *args, "--decimal", decimal,
                        "-o", tmp_path / "comma.json")
    assert code == 0, err
    dot = json.loads((tmp_path / "dot.json").read_text())["samples"]
    comma = json.loads((tmp_path / "comma.json").read_text())["samples"]
    assert comma == dot


def test_decimal_comma_errors_are_one_line(tmp_path, capsys):
    comma_csv = tmp_path / "comma.csv"
    _three_reflector_csv(comma_csv, separator=";", decimal=",")
    lines = comma_csv.read_text().splitlines()
    cells = lines[4].split(";")
    cells[7] = "0.25"  # a decimal point in a decimal-comma file: ambiguous
    lines[4] = ";".join(cells)
    comma_csv.write_text("\n".join(lines) + "\n")
    args = ["--method", "world_point", "--robot", "ur5e", "--columns", REFLECTORS,
            "-o", tmp_path / "o.json"]
    code, _, err = _run(capsys, comma_csv, *args)
    _one_line_exit_2(code, err, "row 5", "'y1'", "'0.25' is not a number", "decimal commas")
    # a first row of whole numbers shows no decimal comma: the next row's says --decimal ,
    lines = comma_csv.read_text().splitlines()
    lines[1] = ";".join(str(k - 3) for k in range(len(lines[1].split(";"))))
    comma_csv.write_text("\n".join(lines) + "\n")
    code, _, err = _run(capsys, comma_csv, *args)
    _one_line_exit_2(code, err, "row 3", "is not a number", "give --decimal ,")
    dot_csv = tmp_path / "dot.csv"
    _three_reflector_csv(dot_csv)
    code, _, err = _run(capsys, dot_csv, *args, "--decimal", ",")
    _one_line_exit_2(code, err, "separated by commas too")
    assert not (tmp_path / "o.json").exists()


EULER = [("zyx", True), ("zyx", False), ("xyz", True), ("xyz", False), ("zyz", True),
         ("zxz", False), ("yxz", True), ("xyx", False)]


@pytest.mark.parametrize(("sequence", "intrinsic"), EULER,
                         ids=[f"{s}-{'in' if i else 'ex'}trinsic" for s, i in EULER])
def test_euler_sequences_convert_exactly_to_roll_pitch_yaw(tmp_path, capsys, sequence,
                                                           intrinsic):
    rpy = np.random.default_rng(6).uniform([-3, -1.4, -3], [3, 1.4, 3], size=(10, 3))
    R = rpy_to_matrix(rpy)
    angles = Rotation.from_matrix(R).as_euler(sequence.upper() if intrinsic else sequence,
                                              degrees=True)
    lines = ["a,b,c,d,e,f,x,y,z,A,B,C"]
    lines += [",".join(["0.1"] * 9 + [repr(float(v)) for v in row]) for row in angles]
    csv_path, out = tmp_path / "euler.csv", tmp_path / "euler.json"
    csv_path.write_text("\n".join(lines) + "\n")
    kind = "intrinsic" if intrinsic else "extrinsic"
    code, _, err = _run(capsys, csv_path, "--method", "world_pose", "--robot", "ur5e",
                        "--no-guess", "--columns", "q=a:f,x=x,y=y,z=z,e1=A,e2=B,e3=C",
                        "--euler", f"{sequence}-{kind}", "--angle-unit", "deg", "-o", out)
    assert code == 0, err
    got = np.array([s["rpy"] for s in json.loads(out.read_text())["samples"]])
    np.testing.assert_allclose(got, rpy, atol=1e-12, rtol=0)


@pytest.mark.parametrize(("extra", "columns", "fragments"), [
    (["--euler", "zyq-intrinsic"], "e1=A,e2=B,e3=C", ["--euler: 'zyq-intrinsic'", "zyz"]),
    (["--euler", "zyx"], "e1=A,e2=B,e3=C", ["SEQ-intrinsic or SEQ-extrinsic"]),
    ([], "e1=A,e2=B,e3=C", ["--euler zyx-intrinsic"]),
    (["--euler", "zyx-intrinsic"], "roll=A,pitch=B,yaw=C", ["e1, e2, e3"]),
    (["--euler", "zyx-intrinsic"], "e1=A,e2=B", ["euler lacks e3"]),
    (["--euler", "zyx-intrinsic", "--angle-unit", "deg"], "e1=A,e2=B,e3=C",
     ["row 2", "'B'", "'ten' is not a number"]),
])
def test_bad_euler_input_is_one_line(tmp_path, capsys, extra, columns, fragments):
    csv_path = tmp_path / "euler.csv"
    csv_path.write_text("a,b,c,d,e,f,x,y,z,A,B,C\n" + ",".join(["0.1"] * 10)
                        + ",ten,0.3\n")
    code, _, err = _run(capsys, csv_path, "--method", "world_pose", "--robot", "ur5e",
                        "--no-guess", "--columns", f"q=a:f,x=x,y=y,z=z,{columns}", *extra,
                        "-o", tmp_path / "o.json")
    _one_line_exit_2(code, err, *fragments)


def test_temperature_and_per_axis_sigmas_reach_every_sample(tmp_path, capsys):
    q, points = _tracker_truth()
    sigmas = np.random.default_rng(9).uniform(0.005, 0.05, size=(len(q), 3))  # mm
    temperature = np.linspace(20.5, 23.25, len(q))
    lines = ["J1,J2,J3,J4,J5,J6,X [mm],Y [mm],Z [mm],sX [mm],sY [mm],sZ [mm],T"]
    lines += [",".join(repr(float(v)) for v in (*q[i], *points["a"][i] * 1e3, *sigmas[i],
                                                temperature[i])) for i in range(len(q))]
    csv_path, out = tmp_path / "s.csv", tmp_path / "s.json"
    csv_path.write_text("\n".join(lines) + "\n")
    code, _, err = _run(capsys, csv_path, "--method", "world_point", "--robot", "ur5e",
                        "--columns", "q=J1:J6,x=X,y=Y,z=Z,sx=sX,sy=sY,sz=sZ,temperature=T",
                        "-o", out)
    assert code == 0, err
    samples = json.loads(out.read_text())["samples"]
    assert all("sigma" not in s for s in samples)
    expected = np.zeros((len(q), 3, 3))
    expected[:, [0, 1, 2], [0, 1, 2]] = (sigmas * 1e-3) ** 2
    np.testing.assert_allclose([s["cov"] for s in samples], expected, rtol=1e-12, atol=0)
    np.testing.assert_array_equal([s["temperature"] for s in samples], temperature)
    dataset = load_dataset(out)
    np.testing.assert_allclose(dataset.samples.cov, expected, rtol=1e-12, atol=0)
    np.testing.assert_array_equal(dataset.samples.temperature, temperature)


def test_per_axis_sigmas_of_a_pose_and_of_each_reflector(tmp_path, capsys):
    pose_csv, out = tmp_path / "pose.csv", tmp_path / "pose.json"
    pose_csv.write_text("a,b,c,d,e,f,x,y,z,r,p,w,sx,sy,sz,temp\n"
                        + ",".join(["0.1"] * 12 + ["0.001", "0.002", "0.003", "21.5"]) + "\n")
    code, _, err = _run(capsys, pose_csv, "--method", "world_pose", "--robot", "ur5e",
                        "--no-guess", "--sigma-angle", "0.002", "--columns",
                        "q=a:f,x=x,y=y,z=z,roll=r,pitch=p,yaw=w,sx=sx,sy=sy,sz=sz,"
                        "temperature=temp", "-o", out)
    assert code == 0, err
    sample = json.loads(out.read_text())["samples"][0]
    np.testing.assert_allclose(sample["cov"], np.diag([1e-6, 4e-6, 9e-6, 4e-6, 4e-6, 4e-6]),
                               rtol=1e-12, atol=0)
    assert sample["temperature"] == 21.5 and "sigma_angle" not in sample
    assert load_dataset(out).samples.n == 1
    # one reflector's per-axis sigmas: sigma.NAME=FIRST:LAST
    csv_path, out = tmp_path / "three.csv", tmp_path / "three.json"
    _three_reflector_csv(csv_path)
    text = csv_path.read_text().splitlines()
    csv_path.write_text("\n".join([text[0] + ",s1,s2,s3"]
                                  + [line + ",0.001,0.002,0.003" for line in text[1:]]) + "\n")
    code, _, err = _run(capsys, csv_path, "--method", "world_point", "--robot", "ur5e",
                        "--no-guess", "--columns", "q=J1:J6,marker.a=x1:z1,sigma.a=s1:s3",
                        "-o", out)
    assert code == 0, err
    np.testing.assert_allclose(json.loads(out.read_text())["samples"][0]["cov"],
                               np.diag([1e-6, 4e-6, 9e-6]), rtol=1e-12, atol=0)


@pytest.mark.parametrize(("columns", "cell", "fragments"), [
    ("sx=sX,sy=sY,sz=sZ,temperature=T", ("sY", "0"), ["row 3", "'sY'", "must be positive"]),
    ("sx=sX,sy=sY,sz=sZ,temperature=T", ("T", "warm"), ["row 3", "'T'", "'warm' is not a"]),
    ("sx=sX,sy=sY", None, ["need all of sx, sy, sz"]),
    ("sx=sX,sy=sY,sz=sZ,sigma=sX", None, ["sigma= or sx=, sy=, sz=, not both"]),
])
def test_bad_sigma_and_temperature_are_one_line(tmp_path, capsys, columns, cell, fragments):
    header = ["J1", "J2", "J3", "J4", "J5", "J6", "X", "Y", "Z", "sX", "sY", "sZ", "T"]
    rows = [["0.1"] * 9 + ["0.01", "0.02", "0.03", "21"] for _ in range(3)]
    if cell is not None:
        rows[1][header.index(cell[0])] = cell[1]
    csv_path = tmp_path / "bad.csv"
    csv_path.write_text("\n".join(",".join(r) for r in [header, *rows]) + "\n")
    code, _, err = _run(capsys, csv_path, "--method", "world_point", "--robot", "ur5e",
                        "--columns", f"q=J1:J6,x=X,y=Y,z=Z,{columns}", "-o", tmp_path / "o.json")
    _one_line_exit_2(code, err, *fragments)
    assert not (tmp_path / "o.json").exists()


def test_a_clock_time_column_is_taken_from_the_earliest_row(tmp_path: Path, capsys) -> None:
    """A `t=` column of Unix seconds (a motion-capture or robot clock, 1.6e9 s) is beyond a
    dataset's range of recorded context: the import writes the time since the earliest row
    (so the file it writes loads), differences kept; a run time is kept as written."""
    q, points = _tracker_truth()
    clock = 1637924760.607069 + 15.0 * np.arange(len(q))[::-1]  # rows not in time order
    for name, times, expected in (("clock", clock, clock - clock.min()),
                                  ("run", 3.0 + np.arange(len(q)), 3.0 + np.arange(len(q)))):
        csv = tmp_path / f"{name}.csv"
        rows = ["J1,J2,J3,J4,J5,J6,x,y,z,t"] + [
            ",".join(repr(float(v)) for v in (*q[i], *points["a"][i], times[i]))
            for i in range(len(q))]
        csv.write_text("\n".join(rows) + "\n")
        out = tmp_path / f"{name}.json"
        code, _, err = _run(capsys, csv, "--method", "world_point", "--robot", "ur5e",
                            "--columns", "q=J1:J6,x=x,y=y,z=z,t=t", "-o", out)
        assert code == 0, err
        t = load_dataset(out).samples.t
        assert t is not None
        assert np.allclose(t, expected, rtol=0, atol=1e-6)
