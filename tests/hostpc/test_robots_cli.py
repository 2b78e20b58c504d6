"""`hostpc robots`: the built-in robots, one robot's table, a URDF chain; bad input is one
line, exit 2. And `hostpc import` with a URDF robot writes its path relative to the output."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from hostpc.cli.main import main

URDF = Path(__file__).resolve().parents[1] / "data" / "arm7_prismatic.urdf"


def test_lists_the_built_in_robots(capsys):
    assert main(["robots", "--json"]) == 0
    entries = {e["name"]: e for e in json.loads(capsys.readouterr().out)}
    assert {"ur5e", "ur10e", "industrial6", "humanoid_upper"} <= set(entries)
    assert entries["ur10e"]["joints"] == 6 and entries["humanoid_upper"]["kind"] == "tree"
    assert main(["robots"]) == 0
    assert "URDF" in capsys.readouterr().out


def test_describes_a_urdf_chain(capsys):
    assert main(["robots", "--robot", str(URDF), "--base-link", "base_link", "--tip-link",
                 "tool0", "--json"]) == 0
    description = json.loads(capsys.readouterr().out)
    assert [j["type"] for j in description["joints"]] == ["prismatic"] + ["revolute"] * 6
    assert description["mounts"] is True
    assert main(["robots", "--robot", "ur5e"]) == 0
    assert "ur5e (DH)" in capsys.readouterr().out


def test_bad_robot_is_one_line(capsys):
    for argv, message in ((["--robot", "nope"], "unknown robot 'nope'"),
                          (["--robot", str(URDF), "--base-link", "x", "--tip-link", "tool0"],
                           "base_link 'x'")):
        assert main(["robots", *argv]) == 2
        err = capsys.readouterr().err
        assert message in err and len(err.strip().splitlines()) == 1


def test_import_with_a_urdf_robot_writes_a_relative_path(tmp_path, capsys):
    rng = np.random.default_rng(0)
    rows = ["lift (mm),j1,j2,j3,j4,j5,j6,X,Y,Z"]
    for _ in range(6):
        rows.append(",".join([f"{rng.uniform(0, 400):.3f}",
                              *(f"{v:.6f}" for v in rng.uniform(-2, 2, 6)),
                              *(f"{v:.6f}" for v in rng.uniform(-1, 1, 3))]))
    (tmp_path / "in.csv").write_text("\n".join(rows) + "\n")
    out = tmp_path / "sets" / "arm.json"
    out.parent.mkdir()
    assert main(["import", str(tmp_path / "in.csv"), "--method", "world_point", "--robot",
                 str(URDF), "--base-link", "base_link", "--tip-link", "tool0", "--no-guess",
                 "--columns", "q=lift:j6,x=X,y=Y,z=Z", "-o", str(out)]) == 0
    document = json.loads(out.read_text())
    assert (out.parent / document["robot"]["urdf"]).resolve() == URDF
    lift_mm = float(rows[1].split(",")[0])
    assert document["samples"][0]["q"][0] == lift_mm / 1000.0  # prismatic: a length
