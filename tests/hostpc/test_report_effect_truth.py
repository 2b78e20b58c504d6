"""The report states thermal expansion and joint coupling with their sigma and against the
simulator's truth: read back from the rendered HTML. Thermal expansion (links growing with
the time since the start) is hidden in the data; the simulator has no joint coupling, so
its truth is 0."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from hostpc.dataset import Dataset
from hostpc.diagnostics import Diagnosis, diagnose
from hostpc.fitting import fit
from hostpc.kinematics import get_robot
from hostpc.report import render_calibration_html
from hostpc.report.effect_sizes import thermal_truth, true_value
from hostpc.synthesize import random_truth, synthesize_stereo_target
from tests.hostpc.report_parse import ReportReader

RATE = 5e-8  # 1/s: the links grow 0.018 % an hour (aluminium warming ~8 K)
N_SAMPLES = 90


def simulator_truth(rate: float, proportional: bool = True) -> dict[str, Any]:
    """The truth dict the simulator writes for a run with a thermal drift (m/s a link)."""
    chain = get_robot("ur5e")
    d = rate * np.asarray(chain.d, float)
    if not proportional:
        d = d * np.linspace(0.5, 1.5, d.size)
    return {"zero_errors": [0.0] * 6,
            "effects": {"thermal_drift": {"d": d.tolist(),
                                          "a": (rate * np.asarray(chain.a, float)).tolist()}}}


def drifting_dataset(temperature: bool) -> Dataset:
    truth = random_truth(np.random.default_rng(7))
    truth["thermal_expansion.e"] = RATE
    record = None if temperature else np.full(N_SAMPLES, np.nan)  # NaN: not recorded
    return synthesize_stereo_target(truth, seed=7, n_samples=N_SAMPLES,
                                    seconds_per_pose=40.0, temperature=record).dataset


@pytest.fixture(scope="module")
def drifting() -> Diagnosis:
    return diagnose(drifting_dataset(temperature=False), "+thermal_expansion,+joint_coupling",
                    cv_folds=0, rank_cv_folds=0, interactions=False)


def test_thermal_expansion_and_coupling_against_the_truth(drifting: Diagnosis) -> None:
    report = ReportReader(render_calibration_html({}, drifting, simulator_truth(RATE)))
    sizes = {r["parameter"]: r for r in report.rows("effect-sizes")}
    result = drifting.fit
    thermal = sizes["thermal_expansion.e"]
    assert thermal["unit"] == "1/s"
    assert float(thermal["value"]) == pytest.approx(result.value("thermal_expansion.e"), rel=1e-4)
    assert float(thermal["sigma"]) == pytest.approx(result.sigma("thermal_expansion.e"), rel=0.03)
    assert float(thermal["true (simulation)"]) == pytest.approx(RATE, rel=1e-4)
    assert abs(float(thermal["(fitted - true) / sigma"])) <= 3.0
    assert result.value("thermal_expansion.e") > 5 * result.sigma("thermal_expansion.e")  # seen
    couplings = [name for name in sizes if name.startswith("joint_coupling.")]
    assert couplings == ["joint_coupling.k5_4", "joint_coupling.k4_5", "joint_coupling.k6_5",
                         "joint_coupling.k5_6"]
    for name in couplings:
        row = sizes[name]
        assert row["unit"] == "rad/rad" and float(row["true (simulation)"]) == 0.0
        if row["sigma"] != "held (unidentifiable)":
            assert float(row["sigma"]) == pytest.approx(result.sigma(name), rel=0.03)
            assert abs(float(row["(fitted - true) / sigma"])) <= 3.0, row


def test_a_drift_that_is_not_thermal_expansion_is_not_compared(drifting: Diagnosis) -> None:
    report = ReportReader(render_calibration_html({}, drifting,
                                                  simulator_truth(RATE, proportional=False)))
    sizes = {r["parameter"]: r for r in report.rows("effect-sizes")}
    assert sizes["thermal_expansion.e"]["true (simulation)"] == "not simulated by name"
    assert thermal_truth({"zero_errors": [0.0] * 6, "effects": {}}, drifting.fit) == 0.0
    assert thermal_truth({"zero_errors": [0.0] * 7, "effects": {}}, drifting.fit) is None
    assert thermal_truth(None, drifting.fit) is None


def test_a_drift_per_second_is_not_compared_with_an_expansion_per_kelvin() -> None:
    per_kelvin = fit(drifting_dataset(temperature=True), "+thermal_expansion", cv_folds=0)
    assert per_kelvin.parameters["thermal_expansion.e"].unit == "1/K"
    assert thermal_truth(simulator_truth(RATE), per_kelvin) is None


def test_coupling_truth_by_name() -> None:
    truth = {"zero_errors": [0.0] * 6, "effects": {"joint_coupling": {"k6_5": 1e-3}}}
    assert true_value(truth, "joint_coupling.k6_5", 6) == 1e-3
    assert true_value(truth, "joint_coupling.k5_6", 6) == 0.0
    assert true_value(truth, "joint_coupling.left.k6_5", 6) is None
    assert true_value({"zero_errors": [0.0] * 6, "effects": {}}, "joint_coupling.k6_5",
                      6) == 0.0
