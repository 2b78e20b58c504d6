"""A calibration's report.html: the verdict, the offsets table and the verification are
read back from the HTML (parsed) and match the result document; older documents render
without placeholders; effect sizes are stated with sigma and against the truth."""

from __future__ import annotations

import copy
import math
import re
from typing import Any

import pytest

from hostpc.diagnostics import Diagnosis, diagnose
from hostpc.report import render_calibration_html, write_calibration_report
from hostpc.report.effect_sizes import true_value
from hostpc.report.markup import DISPLAY
from tests.hostpc.diagnose_support import hidden_dataset
from tests.hostpc.report_parse import ReportReader

PLACEHOLDERS = re.compile(r"DATASET|\bNone\b|\bnan\b|\{[a-z_]+\}|TODO")


def joint(j: int, old: float, correction: float | None, sigma: float | None,
          note: str = "") -> dict[str, Any]:
    pushed = correction is not None
    return {"joint": j + 1, "label": f"q{j + 1}", "old_deg": old,
            "correction_deg": correction, "sigma_deg": sigma,
            "new_deg": old + (correction or 0.0), "pushed": pushed, "note": note}


def document() -> dict[str, Any]:
    """A result document as hostpc.calibrate.summary writes it (a simulated, pushed run whose
    verification passed by the RMS rule of older versions)."""
    corrections = [-0.16803, 0.11176, 0.00770, -0.34386, 0.30408]
    joints = [joint(j, 0.01 * j, c, 1e-4 * (j + 1)) for j, c in enumerate(corrections)]
    joints.append(joint(5, 0.05, None, None, "unidentifiable (not separable from tool.rz)"))
    return {
        "format": "zerocal-calibration/1", "run_dir": "/runs/cal-7", "method": "stereo_target",
        "robot": {"address": "127.0.0.1:5000", "sim": True, "name": "ur5e"},
        "known": ["target"],
        "plan": {"n_poses": 60, "n_verify": 10},
        "acquisition": {"n_planned": 60, "n_measured": 60, "n_skipped": 0, "skipped": []},
        "fit": {"converged": True, "effects": ["joint_offsets", "tool"], "rms_mm": 0.0233,
                "max_mm": 0.0974, "chi2_dof": 0.439, "chi2_dof_upper": 1.370,
                "unidentifiable": ["joint_offsets.q6 and tool.rz are not separable"]},
        "offsets": {"joints": joints},
        "push": {"status": "pushed", "reason": None, "rollback_id": "rb-1"},
        "verify": {"n_planned": 10, "n_measured": 10, "rms_before_mm": 4.2567,
                   "rms_after_mm": 0.0103, "max_before_mm": 5.22, "max_after_mm": 0.0158,
                   "noise_rms_mm": 0.0169, "factor": 1.2, "threshold_mm": 0.0203,
                   "passed": True, "pushed": True},
        "truth": {"zero_errors_deg": [c - 1e-4 for c in corrections] + [-0.48],
                  "joint_offsets_error_deg": [1e-4] * 4 + [-4e-4, None],
                  "within_3_sigma": [True, True, True, True, False, None],
                  "max_abs_error_deg": 4e-4},
        "exit_code": 0,
    }


def read(result: dict[str, Any], diagnosis: Diagnosis | None = None,
         truth: dict[str, Any] | None = None) -> ReportReader:
    text = render_calibration_html(result, diagnosis, truth)
    assert text.startswith("<!DOCTYPE html>") and "<script" not in text
    visible = re.sub(r"<[^>]+>", " ", text)
    assert not PLACEHOLDERS.search(visible), PLACEHOLDERS.search(visible)
    return ReportReader(text)


def test_verdict_offsets_and_truth_read_back() -> None:
    result = document()
    report = read(result)
    assert report.texts["verdict"].startswith("PASS: offsets pushed and verified")
    assert "rollback id rb-1" in report.texts["verdict"]
    assert "Exit code 0." in report.texts["verdict"]
    rows = report.rows("offsets")
    assert [r["joint"] for r in rows] == ["J1", "J2", "J3", "J4", "J5", "J6"]
    for row, source in zip(rows, result["offsets"]["joints"], strict=True):
        assert float(row["old [deg]"]) == pytest.approx(source["old_deg"], abs=1e-5)
        assert float(row["new [deg]"]) == pytest.approx(source["new_deg"], abs=1e-5)
        if source["correction_deg"] is None:
            assert row["correction [deg]"] == row["+/- sigma [deg]"] == "-"
            assert row["pushed"].startswith("no: unidentifiable")
        else:
            assert float(row["correction [deg]"]) == pytest.approx(source["correction_deg"],
                                                                   abs=1e-5)
            assert float(row["+/- sigma [deg]"]) == pytest.approx(source["sigma_deg"],
                                                                  abs=1e-5)
            assert row["pushed"] == "yes"
    assert [r["within 3 sigma"] for r in rows] == ["yes"] * 4 + ["NO", "-"]
    assert float(rows[4]["fitted - true [deg]"]) == pytest.approx(-4e-4)
    assert report.texts["truth-summary"].startswith("4 of 5 identifiable zero offsets")
    verification = dict(report.tables["verification"][1:])  # type: ignore[arg-type]
    assert verification["RMS with the fitted offsets [mm]"] == "0.0103"


def test_new_verification_statistic_and_fail() -> None:
    result = document()
    result["verify"] = {  # as hostpc.calibrate.verify writes it since the chi-square test
        "verdict": "FAIL", "statistic": 41.7, "dof": 30, "p_value": 0.0004, "alpha": 0.01,
        "rms_mm": 0.031, "tolerance_mm": None, "n_poses": 10, "n_planned": 10,
        "n_measured": 10, "rms_before_mm": 4.2, "max_before_mm": 5.1, "rms_after_mm": 0.031,
        "max_after_mm": 0.05, "stated_noise_rms_mm": 0.025, "factor": 1.2,
        "reason": "p = 0.0004 < alpha = 0.01", "passed": False, "pushed": True,
        "kind": "offsets"}
    result["exit_code"] = 6
    report = read(result)
    assert report.texts["verdict"].startswith("FAIL: the pushed offsets failed verification")
    assert "Exit code 6." in report.texts["verdict"]
    rows = dict(report.tables["verification"][1:])  # type: ignore[arg-type]
    assert rows["verdict"] == "FAIL" and rows["degrees of freedom"] == "30"
    assert float(rows["test statistic"]) == pytest.approx(41.7)
    assert float(rows["p-value (a statistic this large if the offsets are right)"]) == 0.0004
    assert rows["false-FAIL rate (alpha)"] == "0.01"
    assert rows["task-space tolerance [mm]"] == "none set"
    assert rows["why it failed"] == "p = 0.0004 < alpha = 0.01"
    assert rows["RMS with the fitted offsets [mm]"] == "0.0310"
    assert "RMS after the push [mm]" not in rows and "poses planned" not in rows  # twins
    assert not any(label.startswith("pass if RMS after") for label in rows)  # old rule
    result["verify"].update(verdict="PASS", tolerance_mm=0.05, reason="", passed=True)
    result["exit_code"] = 0
    report = read(result)
    assert report.texts["verdict"].startswith("PASS")
    assert dict(report.tables["verification"][1:])["task-space tolerance [mm]"] == "0.0500"  # type: ignore[arg-type]


@pytest.mark.parametrize(("status", "head", "css"), [
    ("refused", "NOT PUSHED: the guard rails refused the push", "bad"),
    ("disabled", "NOT PUSHED: --no-push", "neutral"),
    ("rolled_back", "NOT PUSHED: this run's push was rolled back", "neutral"),
    ("nothing", "NOT PUSHED: no identifiable joint offset", "neutral"),
])
def test_not_pushed_says_why(status: str, head: str, css: str) -> None:
    result = document()
    result["push"] = {"status": status,
                      "reason": "chi2/dof 3.1 above its band 1.37" if status == "refused"
                      else None}
    result["verify"]["pushed"] = False
    result["verify"]["passed"] = False
    text = render_calibration_html(result)
    report = ReportReader(text)
    assert report.texts["verdict"].startswith(head)
    assert f'class="verdict {css}" id="verdict"' in text
    assert "Model check on fresh poses (nothing pushed)" in report.texts["verdict"]
    if status == "refused":
        assert "chi2/dof 3.1 above its band 1.37" in report.texts["verdict"]


def test_an_old_or_sparse_document_degrades_gracefully() -> None:
    """No verify, no truth, no plan, no exit code: those parts are left out, never shown as
    placeholders; the offsets table still reads back."""
    result = document()
    for key in ("verify", "truth", "plan", "acquisition", "exit_code", "known", "run_dir"):
        result.pop(key)
    report = read(result)
    assert report.texts["verdict"].startswith("PUSHED, NOT VERIFIED")
    assert "truth-summary" not in report.texts and "verification" not in report.tables
    assert len(report.rows("offsets")) == 6
    assert "within 3 sigma" not in report.tables["offsets"][0]
    assert len(read({}).texts["verdict"]) > 0  # even an empty document renders


@pytest.fixture(scope="module")
def compliance() -> tuple[Diagnosis, dict[str, Any]]:
    """A fit with joint compliance on data with hidden compliance, and the truth dict the
    simulator would write for it."""
    hidden = {"joint_compliance.c2": 2.0e-5, "joint_compliance.c3": 2.5e-5}
    synthetic = hidden_dataset(hidden, seed=2, n_samples=80)
    diagnosis = diagnose(synthetic.dataset, "+joint_compliance,+encoder_scale", cv_folds=0,
                         rank_cv_folds=0, interactions=False, source="hidden.json")
    truth = {"zero_errors": [0.0] * 6,
             "effects": {"joint_compliance": [0.0, 2.0e-5, 2.5e-5, 0.0, 0.0, 0.0]}}
    return diagnosis, truth


def test_effect_sizes_with_sigma_against_the_truth(
        compliance: tuple[Diagnosis, dict[str, Any]], tmp_path: Any) -> None:
    diagnosis, truth = compliance
    path = write_calibration_report(tmp_path / "report.html", document(), diagnosis, truth)
    report = ReportReader(path.read_text(encoding="utf-8"))
    assert "model-verdict" in report.texts  # the diagnosis follows the result
    sizes = {r["parameter"]: r for r in report.rows("effect-sizes")}
    assert not any(name.startswith("joint_offsets.") for name in sizes)  # in the offsets
    fit = diagnosis.fit
    for name in ("joint_compliance.c2", "joint_compliance.c3", "encoder_scale.s2"):
        row = sizes[name]
        unit, factor = DISPLAY[fit.parameters[name].unit]  # deg/(kN m), ppm
        assert row["unit"] == unit
        assert float(row["value"]) / factor == pytest.approx(fit.value(name), rel=1e-4)
        assert float(row["sigma"]) / factor == pytest.approx(fit.sigma(name), rel=0.03)
        assert abs(float(row["(fitted - true) / sigma"])) <= 3.0, (name, row)
    assert float(sizes["joint_compliance.c2"]["true (simulation)"]) == pytest.approx(
        math.degrees(2.0e-5) * 1e3, rel=1e-4)  # deg/(kN m)
    assert float(sizes["encoder_scale.s2"]["true (simulation)"]) == 0.0  # not injected: zero
    assert sizes["tool.x"]["true (simulation)"] == "not simulated by name"
    without = ReportReader(render_calibration_html(document(), diagnosis, None))
    assert "true (simulation)" not in without.tables["effect-sizes"][0]


def test_true_value_mapping() -> None:
    truth = {"zero_errors": [0.0] * 6,
             "effects": {"backlash": [1e-4] * 6, "encoder_scale": [0, 2e-4, 0, 0, 0, 0],
                         "transmission_harmonic": [[0, 0, 0, 0]] * 3 + [[1e-4, 2e-4, 3e-4,
                                                                          4e-4]] + [[0] * 4] * 2,
                         "probe_trigger_latency_s": 0.002}}
    assert true_value(truth, "backlash.b3", 6) == 1e-4
    assert true_value(truth, "encoder_scale.s2", 6) == 2e-4
    assert true_value(truth, "transmission_harmonic.cos2_q4", 6) == 4e-4
    assert true_value(truth, "trigger_latency.latency", 6) == 0.002
    assert true_value(truth, "joint_compliance.c2", 6) == 0.0  # not injected
    assert true_value(truth, "tool.x", 6) is None
    assert true_value(truth, "backlash.b3", 16) is None  # another robot's truth
    assert true_value(truth, "backlash.left.b3", 6) is None
    assert true_value(None, "backlash.b3", 6) is None
    sparse = copy.deepcopy(truth)
    del sparse["effects"]
    assert true_value(sparse, "backlash.b3", 6) is None


def test_the_joints_table_says_restored_and_host_only() -> None:
    """A joint restored to a reference that did not measure it, and an offset a UR took on
    the host only, are never shown as plain "calibrated" / pushed "yes" (review items 5, 6)."""
    from hostpc.report.calibration import outcome_table

    restored = {"joint": 1, "label": "q1", "status": "calibrated", "source": "data",
                "pushed": True, "verified": True,
                "zero_from": {"reference_run": "/runs/rec", "reference_zero": "as_found"}}
    host = {"joint": 2, "label": "q2", "status": "calibrated", "source": "data",
            "pushed": False, "applied_on_host": True, "verified": True,
            "zero_from": "measurements"}
    html = outcome_table({"outcome": {"joints": [restored, host]}})
    assert "restored to the cell reference of /runs/rec" in html
    assert "host session only" in html
