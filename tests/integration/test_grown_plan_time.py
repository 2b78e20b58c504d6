"""A short plan that grew (its model did not explain the fit: the simulated world with a
hidden joint compliance) predicts the robot time of the plan that ran: result.json's
`plan.predicted_robot_time_s` is the grown plan's and agrees with the robot time spent, the
short plan's beside it; the progress line and the summary's plan line say it
(hostpc.calibrate.run_plan, run_result.plan_as_run; issue 28)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from tests.integration.test_calibrate_remodel import calibrate_hidden


@pytest.mark.slow
def test_a_grown_plan_predicts_the_robot_time_it_spends(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    run, code, stdout, stderr = calibrate_hidden(tmp_path, capsys)  # the default plan
    assert code == 5, stderr  # the lean model does not explain the data: push refused
    result = json.loads(stdout)
    assert result["acquisition"]["more_poses"] is not None  # the plan grew
    plan, spent = result["plan"], result["robot_time_s"]
    grown = plan["predicted_robot_time_s"]
    # the simulator moves as the prediction does: the grown plan's time is what was spent
    assert grown["total"] == pytest.approx(spent["measure"] + spent["verify"], rel=0.01)
    short = plan["predicted_robot_time_short_s"]
    assert grown["total"] > 2 * short["total"]  # 9 + 4 poses grew to 60 + 10
    assert "predicted_robot_time_grown_s" not in plan
    assert (f"the plan's predicted robot time of measure + verify is now "
            f"{grown['total']:.1f} s") in stderr
    summary = (run / "summary.txt").read_text()
    assert f"(predicted robot time of measure + verify {grown['total']:.1f} s)" in summary
    # the robot time line: what was spent, beside the grown plan's prediction
    assert f"planned {grown['total']:.1f} s for measure + verify" in summary
