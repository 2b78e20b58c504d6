"""`hostpc calibrate --robot sim` writes RUN/report.html that opens with the run's result:
the verdict and the offsets table read back from the parsed HTML equal result.json, the
truth columns equal the simulator's, and the hidden-compliance world's effect sizes are
stated against its truth. Real stub subprocess on 127.0.0.1, real report."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest
import yaml

from hostpc.cli.main import main
from hostpc.robots.simulator import default_sim_scenario
from tests.hostpc.report_parse import ReportReader
from tests.integration.test_calibrate_sim import truth_rig_file

SCENARIO = (Path(__file__).resolve().parents[2] / "controller_stub" / "scenarios"
            / "stereo_hidden_compliance.yaml")


@pytest.mark.slow
def test_report_of_a_sim_run_reads_back(tmp_path: Path,
                                        capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "run"
    rig = truth_rig_file(default_sim_scenario(), tmp_path / "rig.json")
    code = main(["calibrate", "--robot", "sim", "--poses", "30", "--verify-poses", "5",
                 "--rig", str(rig), "--out", str(out)])
    stderr = capsys.readouterr().err
    assert code in (0, 6), stderr  # the verdict's exit code, read back below
    result = json.loads((out / "result.json").read_text())
    assert result["files"]["report"] == str(out / "report.html")
    report = ReportReader((out / "report.html").read_text(encoding="utf-8"))

    verdict = report.texts["verdict"]
    passed = (result["verify"].get("verdict") == "PASS" if "verdict" in result["verify"]
              else result["verify"]["passed"])
    assert verdict.startswith("PASS" if passed else "FAIL"), verdict
    assert f"Exit code {result['exit_code']}." in verdict
    rows = report.rows("offsets")
    joints = result["offsets"]["joints"]
    assert len(rows) == len(joints) == 6
    for row, joint, error in zip(rows, joints, result["truth"]["joint_offsets_error_deg"],
                                 strict=True):
        assert float(row["new [deg]"]) == pytest.approx(joint["new_deg"], abs=1e-5)
        assert (row["pushed"] == "yes") == joint["pushed"]
        if error is None:
            assert row["fitted - true [deg]"] == "-"
        else:
            assert float(row["fitted - true [deg]"]) == pytest.approx(error, abs=1e-5)
            assert abs(error) < 0.01
    assert "Diagnosis of the fitted model" in (out / "report.html").read_text()


@pytest.mark.slow
def test_hidden_compliance_effect_sizes_against_the_truth(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The packaged world with hidden joint compliance, fitted with it: the report states
    c2 and c3 with their sigma, next to the simulator's 3e-6 and 4e-6 rad/(N m)."""
    out = tmp_path / "run"
    rig = truth_rig_file(yaml.safe_load(SCENARIO.read_text()), tmp_path / "rig.json")
    code = main(["calibrate", "--robot", "sim", "--scenario", str(SCENARIO), "--known",
                 "target", "--effects", "+joint_compliance", "--no-push", "--verify-poses",
                 "0", "--rig", str(rig), "--out", str(out)])
    assert code == 0, capsys.readouterr().err
    report = ReportReader((out / "report.html").read_text(encoding="utf-8"))
    # the verdict box shows the run's outcome (hostpc.calibrate.outcome): nothing pushed
    assert report.texts["verdict"].startswith("NOT PUSHED: offsets unchanged")
    sizes = {r["parameter"]: r for r in report.rows("effect-sizes")}
    fitted = json.loads((out / "fit.json").read_text())["parameters"]
    for name, true in (("joint_compliance.c2", 3e-6), ("joint_compliance.c3", 4e-6)):
        row, fit = sizes[name], fitted[name]
        degrees = math.degrees(1.0) * 1e3  # the report shows deg/(kN m)
        assert row["unit"] == "deg/(kN m)"
        assert float(row["value"]) == pytest.approx(fit["value"] * degrees, rel=1e-4)
        assert float(row["sigma"]) == pytest.approx(fit["std"] * degrees, rel=0.03)
        assert float(row["true (simulation)"]) == pytest.approx(true * degrees, rel=1e-4)
        z = (fit["value"] - true) / fit["std"]
        assert float(row["(fitted - true) / sigma"]) == pytest.approx(z, abs=0.01)
        # the size is found within 3 sigma or 15 % (the host takes the gravity torque at
        # the commanded angles, the simulator at the physical ones: c2 is ~12 % off, 3.8
        # sigma, on this world; the report marks such a row)
        assert abs(z) <= 3.0 or abs(fit["value"] - true) < 0.15 * true, (name, fit, true)
