"""The calibrated robot out as a URDF (`hostpc fit --write-urdf`), and the URDF inputs that
are refused rather than misread: a mimic joint whose leader is off the chain, xacro
files."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from hostpc.cli.main import main
from hostpc.dataset.reading import dataset_from_dict, load_dataset
from hostpc.model.measurements.predict import predict
from hostpc.model.problem import build_problem

URDF = Path(__file__).resolve().parents[1] / "data" / "arm7_prismatic.urdf"
LINKS = ["--base-link", "base_link", "--tip-link", "tool0"]


def _document(q, points, urdf):
    return {"format": "zerocal-dataset/1", "method": "stereo_target",
            "robot": {"urdf": str(urdf), "base_link": "base_link", "tip_link": "tool0"},
            "frames": {"tool": {"xyz": [0, 0, 0.05], "rpy": [0, 0, 0]},
                       "target": [0.5, 0.2, 0.3]},
            "known": ["tool", "target"],
            "samples": [{"q": list(map(float, r)), "p": list(map(float, p)), "sigma": 1e-4}
                        for r, p in zip(q, points, strict=True)]}


def test_written_urdf_reproduces_the_fitted_model(tmp_path, capsys):
    rng = np.random.default_rng(7)
    q = rng.uniform(-2.0, 2.0, size=(80, 7))
    q[:, 0] = rng.uniform(0.0, 0.5, size=80)  # the prismatic lift, m
    problem = build_problem(dataset_from_dict(_document(q, np.zeros((80, 3)), URDF)),
                            "joint_offsets,geometry")
    truth = np.concatenate([rng.normal(scale=2e-3, size=7),
                            rng.normal(scale=1e-3, size=problem.layout.size - 7)])
    y, _ = predict(problem, truth, jacobian=False)
    dataset = tmp_path / "set.json"
    dataset.write_text(json.dumps(_document(q, y, URDF)))
    out = tmp_path / "calibrated.urdf"
    assert main(["fit", str(dataset), "--robot", str(URDF), *LINKS, "--effects",
                 "joint_offsets,geometry", "--cv-folds", "0", "--json",
                 "--write-urdf", str(out)]) == 0
    captured = capsys.readouterr()
    fitted = json.loads(captured.out)
    assert f"wrote {out}" in captured.err and "joint5" in captured.err
    # the fitted model of the input URDF, at new poses
    q_new = rng.uniform(-2.0, 2.0, size=(40, 7))
    q_new[:, 0] = rng.uniform(0.0, 0.5, size=40)
    before = build_problem(dataset_from_dict(_document(q_new, np.zeros((40, 3)), URDF)),
                           "joint_offsets,geometry")
    x = np.array([fitted["parameters"][name]["value"] for name in before.layout.names])
    expected, _ = predict(before, x, jacobian=False)
    # the nominal model of the written URDF: every parameter zero
    after = build_problem(dataset_from_dict(_document(q_new, np.zeros((40, 3)), out)),
                          "joint_offsets,geometry")
    got, _ = predict(after, np.zeros(after.layout.size), jacobian=False)
    assert np.max(np.abs(got - expected)) < 1e-9
    true_points, _ = predict(before, truth, jacobian=False)
    assert np.max(np.abs(got - true_points)) < 1e-9  # noise-free data: the truth as well
    assert "calibrated by zerocal" in out.read_text()


def test_write_urdf_refuses_a_robot_without_a_urdf(tmp_path, capsys):
    doc = _document([[0.1] * 7], [[0.5, 0.2, 0.3]], URDF)
    doc["robot"] = {"convention": "dh", "joints": [
        {"a": 0.3, "alpha": 0.0, "d": 0.0, "theta": 0.0} for _ in range(7)]}
    dataset = tmp_path / "set.json"
    dataset.write_text(json.dumps(doc))
    load_dataset(dataset)
    assert main(["fit", str(dataset), "--cv-folds", "0", "--write-urdf",
                 str(tmp_path / "o.urdf")]) == 2
    err = capsys.readouterr().err.strip()
    assert "not a URDF robot" in err and "--robot FILE.urdf" in err and "\n" not in err
    assert not (tmp_path / "o.urdf").exists()


def _with_mimic(tmp_path: Path) -> Path:
    text = URDF.read_text().replace(
        '<joint name="joint2" type="revolute">',
        '<joint name="joint2" type="revolute"><mimic joint="joint1" multiplier="1"/>')
    assert "<mimic" in text
    path = tmp_path / "mimic.urdf"
    path.write_text(text)
    return path


def test_mimic_joint_whose_leader_is_off_the_chain_is_refused(tmp_path, capsys):
    """A coupled joint needs its leader on the chain (tests/hostpc/test_urdf_mimic.py for
    the coupling itself): a chain that starts after joint1 cannot move joint2 with it."""
    path = _with_mimic(tmp_path)
    assert main(["robots", "--robot", str(path), *LINKS]) == 0  # leader on the chain: fine
    assert "joint 3 follows joint 2" in capsys.readouterr().out
    assert main(["robots", "--robot", str(path), "--base-link", "shoulder",
                 "--tip-link", "tool0"]) == 2
    err = capsys.readouterr().err.strip()
    assert "'joint2' mimics joint 'joint1'" in err and "\n" not in err
    assert "is not a movable joint between shoulder and tool0" in err
    assert err.endswith("--base-link shoulder --tip-link shoulder")


def test_xacro_file_is_refused_with_the_command_that_expands_it(tmp_path, capsys):
    xacro = tmp_path / "arm.urdf.xacro"
    xacro.write_text('<?xml version="1.0"?>\n<robot name="arm" '
                     'xmlns:xacro="http://www.ros.org/wiki/xacro">\n'
                     '  <xacro:property name="l" value="0.3"/>\n  <link name="base_link"/>\n'
                     '</robot>\n')
    assert main(["robots", "--robot", str(xacro), *LINKS]) == 2
    err = capsys.readouterr().err.strip()
    assert err.endswith(f"xacro {xacro} > {tmp_path / 'arm.urdf'}") and "\n" not in err
    disguised = tmp_path / "arm.urdf"  # xacro elements in a .urdf, namespace undeclared
    disguised.write_text('<robot name="arm"><xacro:macro name="m"/><link name="b"/></robot>')
    assert main(["robots", "--robot", str(disguised), *LINKS]) == 2
    assert "xacro " in capsys.readouterr().err
    declared = tmp_path / "arm2.urdf"
    declared.write_text(xacro.read_text())
    assert main(["robots", "--robot", str(declared), *LINKS]) == 2
    assert f"xacro {declared} >" in capsys.readouterr().err


def test_corrected_origins_give_the_fitted_forward_kinematics_exactly():
    """Every kind of delta (offsets incl. the prismatic one, d, a, alpha, Hayati beta)."""
    from hostpc.kinematics.poses import forward
    from hostpc.kinematics.urdf import chain_from_urdf, parse_urdf
    from hostpc.kinematics.urdf_calibrated import calibrated_origins, calibrated_urdf_text

    text = URDF.read_text()
    robot = parse_urdf(text)
    chain = chain_from_urdf(robot, "base_link", "tool0")
    rng = np.random.default_rng(3)
    delta = rng.normal(scale=0.01, size=5 * chain.n)
    delta[4 * chain.n:] *= chain.hayati
    changes = calibrated_origins(robot, "base_link", "tool0", delta)
    assert [c.joint for c in changes] == ["lift"] + [f"joint{i}" for i in range(1, 7)]
    written = chain_from_urdf(parse_urdf(calibrated_urdf_text(text, changes, "test")),
                              "base_link", "tool0")
    q = rng.uniform(-2.0, 2.0, size=(100, chain.n))
    np.testing.assert_allclose(forward(written, q).T_base_flange,
                               forward(chain, q, delta).T_base_flange, atol=1e-11)
    unchanged = calibrated_origins(robot, "base_link", "tool0", np.zeros(5 * chain.n))
    assert max(max(c.translation_mm, c.rotation_deg) for c in unchanged) < 1e-9
