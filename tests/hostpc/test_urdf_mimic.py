"""URDF mimic joints as coupled joints: the follower (q = multiplier * q_leader + offset) is
not a free joint; its leader's zero offset moves it multiplier times as much, and its own
offset is not fitted. Checked against the plain product of URDF transforms, through the CLI
and the calibrated URDF written back (hostpc.kinematics.urdf, Chain.coupled)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from hostpc.cli.main import main
from hostpc.dataset.reading import dataset_from_dict, load_dataset
from hostpc.fitting import fit
from hostpc.kinematics.urdf import UrdfRobot, load_urdf_chain, parse_urdf
from hostpc.model.measurements.predict import predict
from hostpc.model.problem import build_problem

SOURCE = Path(__file__).resolve().parents[1] / "data" / "arm7_prismatic.urdf"
ORDER = ["base_mount", "lift", "joint1", "joint2", "joint3", "joint4", "joint5", "joint6",
         "flange_joint", "tool0_joint"]
LEADER, FOLLOWER = 2, 3  # joint2 and joint3 in the chain's joint vector (the lift is 0)
MULTIPLIER, OFFSET = 0.5, 0.1
TRUTH = np.array([0.002, 0.01, -0.02, 0.0, 0.015, 0.01, -0.01])  # offsets; the lift in m


@pytest.fixture(scope="module")
def mimic_urdf(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """arm7 with joint3 following joint2: q3 = 0.5 q2 + 0.1 (both about y)."""
    text = SOURCE.read_text().replace(
        '<joint name="joint3" type="revolute">',
        f'<joint name="joint3" type="revolute"><mimic joint="joint2" '
        f'multiplier="{MULTIPLIER}" offset="{OFFSET}"/>')
    path = tmp_path_factory.mktemp("mimic") / "mimic.urdf"
    path.write_text(text)
    return path


def _plain_fk(robot: UrdfRobot, q: np.ndarray) -> np.ndarray:
    """T_base_tool0 as the plain product of URDF transforms (origin, then joint motion)."""
    T, k = np.eye(4), 0
    for name in ORDER:
        joint, motion = robot.joints[name], np.eye(4)
        if joint.type == "prismatic":
            motion[:3, 3] = joint.axis * q[k]
        elif joint.type in ("revolute", "continuous"):
            motion[:3, :3] = Rotation.from_rotvec(joint.axis * q[k]).as_matrix()
        k += joint.type != "fixed"
        T = T @ joint.origin @ motion
    return T


def _document(urdf: Path, n: int = 60, follower_error: float = 0.0) -> dict:
    """world_point samples of a reflector 5 cm past tool0, the robot at TRUTH: the follower
    recorded as the robot reports it (its leader's reading times 0.5 plus 0.1) and moved, in
    truth, by its leader's true angle."""
    robot = parse_urdf(urdf.read_text())
    rng = np.random.default_rng(3)
    q = rng.uniform(-1.5, 1.5, (n, 7))
    q[:, 0] = rng.uniform(0.0, 0.5, n)
    q[:, FOLLOWER] = MULTIPLIER * q[:, LEADER] + OFFSET
    true = q + TRUTH
    true[:, FOLLOWER] = MULTIPLIER * (q[:, LEADER] + TRUTH[LEADER]) + OFFSET
    points = np.array([(_plain_fk(robot, t) @ [0.0, 0.0, 0.05, 1.0])[:3] for t in true])
    q[5, FOLLOWER] += follower_error
    return {"format": "zerocal-dataset/1", "method": "world_point",
            "robot": {"urdf": str(urdf), "base_link": "base_link", "tip_link": "tool0"},
            "frames": {"world": {"xyz": [0, 0, 0], "rpy": [0, 0, 0]},
                       "markers": {"m": [0, 0, 0.05]}},
            "known": ["world", "markers"],
            "samples": [{"q": list(map(float, a)), "p": list(map(float, b)), "sigma": 1e-5,
                         "marker": "m"} for a, b in zip(q, points, strict=True)]}


def test_the_urdf_chain_records_the_coupling(mimic_urdf: Path) -> None:
    chain = load_urdf_chain(mimic_urdf, "base_link", "tool0")
    assert chain.n == 7 and chain.coupled == ((FOLLOWER, LEADER, MULTIPLIER, OFFSET),)


def test_the_leaders_offset_moves_the_follower(mimic_urdf: Path) -> None:
    result = fit(dataset_from_dict(_document(mimic_urdf)), ["joint_offsets"], cv_folds=0)
    assert result.converged and result.rms < 1e-9  # noise-free: the truth exactly
    np.testing.assert_allclose(result.x, TRUTH, atol=1e-9)
    assert list(result.fixed) == [k == FOLLOWER for k in range(7)]  # not fitted on its own
    assert result.x[FOLLOWER] == 0.0


def test_a_follower_off_its_coupling_is_one_line(mimic_urdf: Path, tmp_path: Path,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "off.json"
    path.write_text(json.dumps(_document(mimic_urdf, follower_error=0.01)))
    assert main(["fit", str(path)]) == 2
    err = capsys.readouterr().err.strip()
    # the URDF's names (the joint vector's q4/q3 beside them) and the command's options
    assert "\n" not in err and "joint3 (q4) follows joint2 (q3)" in err and "sample #5" in err
    assert (f"--robot {mimic_urdf} --base-link base_link --tip-link upper_arm" in err
            and "import again" in err)


def test_import_refuses_a_follower_off_its_coupling(mimic_urdf: Path, tmp_path: Path,
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    """`hostpc import` checks the follower's column as fit does, one line with its name."""
    document = _document(mimic_urdf, follower_error=0.01)
    rows = ["j1,j2,j3,j4,j5,j6,j7,x,y,z"] + [
        ",".join(f"{v:.12g}" for v in (*s["q"], *s["p"])) for s in document["samples"]]
    (tmp_path / "off.csv").write_text("\n".join(rows) + "\n")
    argv = ["import", str(tmp_path / "off.csv"), "--method", "world_point", "--robot",
            str(mimic_urdf), "--base-link", "base_link", "--tip-link", "tool0", "--columns",
            "q=j1:j7,x=x,y=y,z=z", "-o", str(tmp_path / "off.json")]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "joint3 (q4) follows joint2 (q3)" in err and "sample #5" in err
    assert not (tmp_path / "off.json").exists()


def test_the_calibrated_urdf_keeps_the_coupling(mimic_urdf: Path, tmp_path: Path,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    """The leader's offset folded into its origin and its multiple into the follower's: the
    written file (mimic kept) reproduces the fit's predictions."""
    path = tmp_path / "set.json"
    path.write_text(json.dumps(_document(mimic_urdf)))
    out = tmp_path / "calibrated.urdf"
    assert main(["fit", str(path), "--effects", "joint_offsets,geometry", "--cv-folds", "0",
                 "--write-urdf", str(out)]) == 0
    capsys.readouterr()
    assert "<mimic" in out.read_text()
    document = json.loads(path.read_text())
    document["robot"]["urdf"] = str(out)
    after = build_problem(dataset_from_dict(document), ["joint_offsets"])
    got, _ = predict(after, np.zeros(after.layout.size), jacobian=False)
    measured = np.array([s["p"] for s in document["samples"]])
    assert np.max(np.abs(got - measured)) < 1e-9
    assert load_dataset(path).robot.urdf == str(mimic_urdf)


def test_import_computes_a_follower_the_csv_does_not_have(
        mimic_urdf: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A controller that logs only the independent joints (the follower, joint3 = q4, has
    no column): mapping the others one by one, import computes the follower from its leader
    and the fit recovers the truth; a range over too few columns is one line saying what
    to give."""
    document = _document(mimic_urdf)
    header = ["j1", "j2", "j3", "j5", "j6", "j7", "x", "y", "z"]  # no j4: joint3 (q4)
    rows = [",".join(header)] + [
        ",".join(f"{v:.17g}" for v in (*(q for k, q in enumerate(s["q"]) if k != FOLLOWER),
                                        *s["p"])) for s in document["samples"]]
    (tmp_path / "leaders.csv").write_text("\n".join(rows) + "\n")
    out = tmp_path / "leaders.json"
    argv = ["import", str(tmp_path / "leaders.csv"), "--method", "world_point", "--robot",
            str(mimic_urdf), "--base-link", "base_link", "--tip-link", "tool0", "--no-guess",
            "-o", str(out), "--columns"]
    assert main([*argv, "q=j1:j7,x=x,y=y,z=z"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "missing q7" in err and "q4 follows q3" in err
    assert main([*argv, "q1=j1,q2=j2,q3=j3,q5=j5,q6=j6,q7=j7,x=x,y=y,z=z"]) == 0
    assert "q4 follows q3" in capsys.readouterr().out
    imported = load_dataset(out).samples.q
    np.testing.assert_allclose(imported, [s["q"] for s in document["samples"]], atol=1e-12)
    for sample, q in zip(document["samples"], imported, strict=True):
        sample["q"] = q.tolist()  # the imported joints, the truth's frames (known)
    result = fit(dataset_from_dict(document), ["joint_offsets"], cv_folds=0)
    np.testing.assert_allclose(result.x, TRUTH, atol=1e-9)


def test_a_follower_has_no_joint_space_parameters_of_its_own(mimic_urdf: Path) -> None:
    """Not its offset, and not its compliance, encoder scale or transmission harmonics
    either: the follower moves only with its leader (whose corrections it follows m times),
    so each of its own joint-space parameters moves nothing and the fit holds it."""
    effects = ["joint_offsets", "joint_compliance", "encoder_scale", "transmission_harmonic"]
    result = fit(dataset_from_dict(_document(mimic_urdf)), effects, cv_folds=0)
    own = [n for n in result.names if n.split(".", 1)[1] in
           ("q4", "c4", "s4", "sin1_q4", "cos1_q4", "sin2_q4", "cos2_q4")]
    assert len(own) == 7
    held = dict(zip(result.names, result.fixed, strict=True))
    assert all(held[n] for n in own), [n for n in own if not held[n]]
    assert not held["joint_compliance.c3"] and not held["encoder_scale.s3"]  # the leader's
    assert {d.fixed for d in result.unidentifiable} >= set(own)
