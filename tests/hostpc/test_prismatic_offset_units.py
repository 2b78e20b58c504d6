"""A prismatic joint's zero offset is a length everywhere (docs/conventions.md, "Prismatic
joints"): the fit's parameter unit (m), the text (mm), --json ("m"), priors (mm accepted,
deg refused with the unit that fits), the "not separable" lines, the diagnosis report; and
the other joint-space parameters of that joint follow its type.

The robot is tests/data/arm7_prismatic.urdf (a prismatic lift, then a 6R arm), measured by a
stereo camera with the tool and the target known; the truth injected is a 3 mm zero offset of
the lift and a few mrad on the arm, recovered from noisy samples."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from hostpc.calibrate.offline_push import load_saved_fit
from hostpc.cli.main import main
from hostpc.dataset.reading import dataset_from_dict
from hostpc.errors import InputError
from hostpc.fitting import fit
from hostpc.kinematics.urdf import load_urdf_chain
from hostpc.model import joint_offsets
from hostpc.model.measurements.predict import predict
from hostpc.model.problem import build_problem

URDF = Path(__file__).resolve().parents[1] / "data" / "arm7_prismatic.urdf"
ROBOT = {"urdf": str(URDF), "base_link": "base_link", "tip_link": "tool0"}
NOISE = 1e-4  # m, stated and drawn
LIFT_OFFSET = 3e-3  # m: the lift's injected zero offset
LIFT = joint_offsets.offset_name("q1")


def _document(q: np.ndarray, points: np.ndarray, known: tuple[str, ...] = ("tool", "target")
              ) -> dict[str, object]:
    return {"format": "zerocal-dataset/1", "method": "stereo_target", "robot": ROBOT,
            "frames": {"tool": {"xyz": [0, 0, 0.05], "rpy": [0, 0, 0]},
                       "target": [0.5, 0.2, 0.3]},
            "known": list(known),
            "samples": [{"q": list(map(float, r)), "p": list(map(float, p)), "sigma": NOISE}
                        for r, p in zip(q, points, strict=True)]}


def _truth_dataset(known: tuple[str, ...] = ("tool", "target")) -> tuple[dict[str, object],
                                                                         np.ndarray]:
    """The measured document (3 mm on the lift, 1..4 mrad on the arm, 0.1 mm noise) and the
    injected offsets (7,) in SI."""
    chain = load_urdf_chain(URDF, "base_link", "tool0")
    rng = np.random.default_rng(11)
    q = rng.uniform(np.maximum(chain.q_min, -2.5), np.minimum(chain.q_max, 2.5),
                    size=(60, chain.n))
    nominal = dataset_from_dict(_document(q, np.zeros((len(q), 3)), known))
    problem = build_problem(nominal, "joint_offsets")
    truth = np.array([LIFT_OFFSET, 2e-3, -1e-3, 4e-3, -2e-3, 1e-3, 3e-3])
    x = np.zeros(problem.layout.size)
    x[[problem.layout.index(joint_offsets.offset_name(f"q{j + 1}")) for j in range(7)]] = truth
    y, _ = predict(problem, x, jacobian=False)
    return _document(q, y + rng.normal(scale=NOISE, size=y.shape), known), truth


@pytest.fixture(scope="module")
def measured(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, np.ndarray]:
    document, truth = _truth_dataset()
    path = tmp_path_factory.mktemp("prismatic") / "arm7.json"
    path.write_text(json.dumps(document))
    return path, truth


def test_the_unit_rule_is_the_joints_type() -> None:
    chain = load_urdf_chain(URDF, "base_link", "tool0")
    assert joint_offsets.unit(True) == "m" and joint_offsets.unit(False) == "rad"
    assert joint_offsets.units(chain) == ("m",) + ("rad",) * 6


def test_the_lifts_offset_is_fitted_and_stated_in_metres(measured: tuple[Path, np.ndarray]
                                                         ) -> None:
    path, truth = measured
    document = json.loads(path.read_text())
    result = fit(dataset_from_dict(document), "joint_offsets", cv_folds=0)
    assert result.converged
    lift = result.parameters[LIFT]
    assert lift.unit == "m"
    assert lift.std is not None and lift.std < 2e-4
    assert abs(lift.value - LIFT_OFFSET) < max(4 * lift.std, 1e-4)
    for j in range(1, 7):
        arm = result.parameters[joint_offsets.offset_name(f"q{j + 1}")]
        assert arm.unit == "rad"
        assert arm.std is not None and abs(arm.value - truth[j]) < 4 * arm.std + 1e-5


def test_fit_text_and_json_show_the_lift_in_mm(measured: tuple[Path, np.ndarray],
                                               capsys: pytest.CaptureFixture[str]) -> None:
    path, _ = measured
    assert main(["fit", str(path), "--cv-folds", "0"]) == 0
    text = capsys.readouterr().out
    line = next(row for row in text.splitlines() if row.strip().startswith(LIFT + " "))
    assert line.rstrip().endswith("mm"), line
    value = float(line.split()[1])
    assert value == pytest.approx(LIFT_OFFSET * 1e3, abs=0.2)  # mm, not 0.17 "deg"
    second = next(row for row in text.splitlines()
                  if row.strip().startswith(joint_offsets.offset_name("q2") + " "))
    assert second.rstrip().endswith("deg")
    largest = next(row for row in text.splitlines() if row.startswith("largest joint offset"))
    assert " mm" in largest and " deg" in largest, largest

    assert main(["fit", str(path), "--cv-folds", "0", "--json"]) == 0
    parameters = json.loads(capsys.readouterr().out)["parameters"]
    assert parameters[LIFT]["unit"] == "m"
    assert parameters[LIFT]["value"] == pytest.approx(LIFT_OFFSET, abs=2e-4)
    assert parameters[joint_offsets.offset_name("q2")]["unit"] == "rad"


def test_a_prior_on_the_lift_is_a_length(measured: tuple[Path, np.ndarray],
                                         capsys: pytest.CaptureFixture[str]) -> None:
    path, _ = measured
    dataset = dataset_from_dict(json.loads(path.read_text()))
    # a prior in mm is read as a length: 3 mm +- 0.01 mm pins the lift there
    pinned = fit(dataset, "joint_offsets", priors=[f"{LIFT}=3+-0.01mm"], cv_folds=0)
    assert pinned.value(LIFT) == pytest.approx(3e-3, abs=2e-5)
    assert main(["fit", str(path), "--cv-folds", "0", "--prior", f"{LIFT}=0+-0.1mm"]) == 0
    capsys.readouterr()
    # deg is refused, on one line that names the units that fit
    with pytest.raises(InputError, match=r"unit 'deg' does not fit the parameter's unit 'm'"
                                         r".*give it in m, mm, um"):
        fit(dataset, "joint_offsets", priors=[f"{LIFT}=0+-0.01deg"], cv_folds=0)
    assert main(["fit", str(path), "--prior", f"{LIFT}=0+-0.01deg"]) == 2
    error = capsys.readouterr().err.strip()
    assert len(error.splitlines()) == 1 and "'m'" in error and "mm" in error
    # and a revolute joint's offset still takes deg, not mm
    with pytest.raises(InputError, match="give it in rad, mrad, urad, deg"):
        fit(dataset, "joint_offsets", priors=[f"{joint_offsets.offset_name('q2')}=0+-1mm"],
            cv_folds=0)


def test_not_separable_lines_state_the_lift_in_metres() -> None:
    # with the target estimated, the lift (along the base z) and target.z trade 1 m per m
    document, _ = _truth_dataset(known=("tool",))
    result = fit(dataset_from_dict(document), "joint_offsets,target", cv_folds=0)
    lines = [d.description for d in result.unidentifiable if LIFT in d.parameters]
    assert lines, [d.description for d in result.unidentifiable]
    assert any(" m/m " in line for line in lines), lines
    assert not any("rad/rad" in line and "target" in line for line in lines), lines


def test_the_lifts_other_joint_space_parameters_follow_its_type() -> None:
    document, _ = _truth_dataset()
    problem = build_problem(dataset_from_dict(document),
                            "joint_offsets,joint_compliance,backlash,encoder_scale,geometry")
    unit = dict(zip(problem.layout.names, problem.layout.units, strict=True))
    assert unit["joint_compliance.c1"] == "m/N" and unit["joint_compliance.c2"] == "rad/(N m)"
    assert unit["backlash.b1"] == "m" and unit["backlash.b2"] == "rad"
    assert unit["encoder_scale.s1"] == unit["encoder_scale.s2"] == "1"
    # a prismatic joint's d slot is its fixed turn about its axis (conventions.md)
    assert unit["geometry.d1"] == "rad" and unit["geometry.d2"] == "m"
    assert unit["geometry.a1"] == "m"


def test_diagnose_report_shows_the_lift_in_mm(measured: tuple[Path, np.ndarray],
                                              tmp_path: Path,
                                              capsys: pytest.CaptureFixture[str]) -> None:
    path, _ = measured
    report = tmp_path / "report.html"
    main(["diagnose", str(path), "--effects", "joint_offsets", "--cv-folds", "0",
          "--report", str(report)])
    capsys.readouterr()
    html = report.read_text()
    start = html.index(f">{LIFT}<")
    row = html[start:html.index("</tr>", start)]
    assert ">mm<" in row and ">deg<" not in row, row


def test_a_fit_with_the_lifts_offset_is_never_pushed_as_an_angle(
        measured: tuple[Path, np.ndarray], tmp_path: Path,
        capsys: pytest.CaptureFixture[str]) -> None:
    # a controller's zero offsets are radians (protocol/): 3 mm would be written as 3 mrad
    path, _ = measured
    assert main(["fit", str(path), "--cv-folds", "0", "--json"]) == 0
    saved = tmp_path / "fit.json"
    saved.write_text(capsys.readouterr().out)
    with pytest.raises(InputError, match=rf"parameters\.{LIFT} is a prismatic joint's zero "
                                         r"offset \(unit m\).*--write-urdf"):
        load_saved_fit(saved)
    assert load_saved_fit(saved, offsets=False).x.size  # a prediction reads it
    # refused before any connection (nothing listens on 127.0.0.1:9: none is made)
    assert main(["push", str(saved), "--robot", "127.0.0.1:9", "--dry-run"]) == 2
    assert "prismatic" in capsys.readouterr().err
