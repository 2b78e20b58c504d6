"""`--robot FILE.json`: a robot from a DH / modified-DH table file (hostpc.kinematics.
table_file, docs/robots.md), accepted by fit, diagnose, predict, import and robots; a broken
table is one line and exit 2. And `hostpc predict` refuses a fit of another robot."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from hostpc.cli.main import main
from hostpc.dataset import save_dataset
from hostpc.kinematics import forward, get_robot
from hostpc.kinematics.table_file import load_table_chain
from tests.hostpc.diagnose_support import hidden_world_point

DATA = Path(__file__).resolve().parents[1] / "data"
UR5E_TABLE = DATA / "ur5e_dh.json"  # UR's published UR5e DH table, in degrees


def test_the_published_ur5e_table_moves_as_the_built_in_ur5e() -> None:
    table, built_in = load_table_chain(UR5E_TABLE), get_robot("ur5e")
    q = np.random.default_rng(1).uniform(-2 * np.pi, 2 * np.pi, (200, 6))
    difference = forward(table, q).T_base_flange - forward(built_in, q).T_base_flange
    assert np.max(np.abs(difference)) < 1e-12
    assert np.allclose(table.q_min, np.radians(-360.0)) and table.n == 6


def test_mdh_prismatic_and_units(tmp_path: Path) -> None:
    """A modified-DH table in mm with a prismatic joint: the chain of the same rows in SI."""
    path = tmp_path / "gantry.json"
    path.write_text(json.dumps({"convention": "mdh", "units": {"length": "mm", "angle": "deg"},
                                "joints": [{"a": 0, "alpha": 0, "d": 0, "theta": 0,
                                            "type": "prismatic", "min": 0, "max": 500},
                                           {"a": 100, "alpha": -90, "d": 20, "theta": 90}]}))
    chain = load_table_chain(path)
    assert chain.convention == "mdh" and list(chain.joint_is_prismatic) == [True, False]
    assert np.allclose(chain.a, [0.0, 0.1]) and np.allclose(chain.d, [0.0, 0.02])
    assert np.allclose(chain.alpha, [0.0, -np.pi / 2]) and np.isclose(chain.q_max[0], 0.5)


@pytest.fixture(scope="module")
def ur5e_files(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """A world_point dataset of a UR5e (named by the dataset) and its fit (FIT.json)."""
    folder = tmp_path_factory.mktemp("table")
    dataset = hidden_world_point({}, seed=4, n_samples=60).dataset
    save_dataset(dataset, folder / "day.json")
    return folder / "day.json", folder


def _fit_json(args: list[str], capsys: pytest.CaptureFixture[str]) -> dict:
    assert main(["fit", *args, "--json", "--cv-folds", "0"]) == 0
    return json.loads(capsys.readouterr().out)


def test_fit_diagnose_predict_accept_a_table_file(ur5e_files, capsys) -> None:
    day, folder = ur5e_files
    named = _fit_json([str(day)], capsys)
    table = _fit_json([str(day), "--robot", str(UR5E_TABLE)], capsys)
    for name, entry in named["parameters"].items():
        assert table["parameters"][name]["value"] == pytest.approx(entry["value"], abs=1e-9)
    # the same kinematics: the same identity, so predict accepts either fit
    assert table["robot_identity"]["kinematics"] == named["robot_identity"]["kinematics"]
    (folder / "fit.json").write_text(json.dumps(table))
    assert main(["predict", str(folder / "fit.json"), str(day)]) == 0
    assert main(["predict", str(folder / "fit.json"), str(day), "--robot",
                 str(UR5E_TABLE)]) == 0
    capsys.readouterr()
    assert main(["diagnose", str(day), "--robot", str(UR5E_TABLE), "--cv-folds", "0"]) in (0, 1)
    assert "diagnose" in capsys.readouterr().out


def test_import_with_a_table_file(tmp_path: Path, capsys) -> None:
    rows = ["q1,q2,q3,q4,q5,q6,x,y,z"]
    rng = np.random.default_rng(2)
    chain = get_robot("ur5e")
    q = rng.uniform(-1, 1, (12, 6))
    p = forward(chain, q).T_base_flange[:, :3, 3]
    rows += [",".join(f"{v:.9f}" for v in (*qk, *pk)) for qk, pk in zip(q, p, strict=True)]
    (tmp_path / "t.csv").write_text("\n".join(rows) + "\n")
    out = tmp_path / "t.json"
    assert main(["import", str(tmp_path / "t.csv"), "--method", "world_point", "--robot",
                 str(UR5E_TABLE), "--columns", "q=q1:q6,x=x,y=y,z=z", "-o", str(out)]) == 0
    assert f"robot {UR5E_TABLE}" in capsys.readouterr().out  # the table file, never None
    robot = json.loads(out.read_text())["robot"]
    assert robot["convention"] == "dh" and len(robot["joints"]) == 6
    assert robot["joints"][0]["d"] == pytest.approx(0.1625)
    assert robot["joints"][0]["alpha"] == pytest.approx(np.pi / 2)


@pytest.mark.parametrize(("table", "message"), [
    ("not json", "not valid JSON"),
    ({"joints": [{"a": 0, "alpha": 0, "d": 0, "theta": 0}]}, "'convention' missing"),
    ({"convention": "dh", "joints": [{"a": 0, "alpah": 0, "d": 0, "theta": 0}]},
     "joint 1: unknown key 'alpah'"),
    ({"convention": "dh", "joints": [{"a": 0, "alpha": 0, "d": "x", "theta": 0}]},
     "joint 1 d: expected a finite number"),
    ({"convention": "dh", "joints": [{"a": 0, "alpha": 0, "d": 0, "theta": 0, "min": 1}]},
     "give both 'min' and 'max'"),
    ({"convention": "xyz", "joints": []}, "convention 'xyz' is not one of dh, mdh"),
    ({"format": "zerocal-dataset/1", "method": "world_point"},
     "format 'zerocal-dataset/1', expected 'zerocal-robot-table/1'"),
    # implausible units (review item 4): UR's table in degrees without units.angle deg
    ({k: v for k, v in json.loads(UR5E_TABLE.read_text()).items() if k != "units"},
     "joint 1: |alpha| 90 rad > 2 pi rad: the angles look like degrees; set units.angle deg"),
    ({"convention": "dh", "joints": [{"a": 0, "alpha": 0, "d": 0, "theta": 0},
                                     {"a": 42.5, "alpha": 0, "d": 0, "theta": 0}]},
     "joint 2: |a| 42.5 m > 10 m: looks like mm/cm; set units.length mm"),
    ({"convention": "dh", "joints": [{"a": 0, "alpha": 0, "d": 0, "theta": 0,
                                      "type": "prismatic", "min": 0, "max": 500}]},
     "joint 1: |max| 500 m > 10 m: looks like mm/cm"),
])
def test_a_broken_table_is_one_line_and_exit_2(ur5e_files, tmp_path, capsys, table,
                                                message) -> None:
    day, _ = ur5e_files
    path = tmp_path / "bad.json"
    path.write_text(table if isinstance(table, str) else json.dumps(table))
    for argv in (["fit", str(day)], ["diagnose", str(day)], ["robots"],
                 ["import", str(day), "--method", "world_point", "--columns", "q=a:b,x=x,y=y,"
                  "z=z", "-o", str(tmp_path / "o.json")]):
        assert main([*argv, "--robot", str(path)]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and message in err[0] and str(path) in err[0], (argv, err)


def test_predict_refuses_a_fit_of_another_robot(ur5e_files, tmp_path, capsys) -> None:
    """A fit of a UR5e applied to the same poses read as a UR10e (same joint count, same
    parameter names): one line naming both robots and the command that fits this one."""
    day, folder = ur5e_files
    (folder / "ur5e_fit.json").write_text(json.dumps(_fit_json([str(day)], capsys)))
    document = json.loads(day.read_text())
    document["robot"] = {"name": "ur10e"}
    other = tmp_path / "ur10e_day.json"
    other.write_text(json.dumps(document))
    assert main(["predict", str(folder / "ur5e_fit.json"), str(other)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "ur5e" in err[0] and "ur10e" in err[0]
    assert f"hostpc fit {other} --json" in err[0]
    # the same refusal when the other robot comes from --robot (a table file)
    changed = json.loads(UR5E_TABLE.read_text())
    changed["joints"][1]["a"] = -0.4251  # 0.1 mm longer upper arm: another robot
    table = tmp_path / "ur5e_changed.json"
    table.write_text(json.dumps(changed))
    assert main(["predict", str(folder / "ur5e_fit.json"), str(day), "--robot",
                 str(table)]) == 2
    assert "explicit table" in capsys.readouterr().err
