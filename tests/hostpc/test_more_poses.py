"""When a short plan grows: on the chi2 the push guard tests (with the rig's covariance
inside when the fit has it), not on the plain chi2 alone."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from hostpc.calibrate.journal import Journal
from hostpc.calibrate.more_poses import more_poses_reason
from hostpc.calibrate.offline_push import SavedFit
from hostpc.diagnostics.adequacy import chi2_dof_upper
from hostpc.methods.base import Plan

DOF = 40


def saved_fit(chi2_dof: float, with_calibration: float | None) -> SavedFit:
    return SavedFit(names=("joint_offsets.q1",), x=np.zeros(1), std=np.full(1, 1e-5),
                    fixed=np.zeros(1, bool), unidentifiable=(), converged=True, message="",
                    chi2=chi2_dof * DOF, dof=DOF, source="test",
                    chi2_dof_with_calibration=with_calibration)


def plan() -> Plan:
    return Plan(q=np.zeros((20, 6)), q_verify=np.zeros((4, 6)), q_more=np.ones((40, 6)))


def test_grows_when_the_guards_chi2_is_above_its_band(tmp_path: Path) -> None:
    upper = chi2_dof_upper(DOF)
    reason = more_poses_reason(Journal(tmp_path), plan(), saved_fit(2 * upper, None))  # type: ignore[arg-type]
    assert reason is not None and "above its band" in reason
    # journaled: a resume measures the same poses for the same reason
    assert more_poses_reason(Journal(tmp_path), plan(), saved_fit(0.5, None)) == reason  # type: ignore[arg-type]


def test_no_growth_when_the_rig_covariance_explains_the_excess(tmp_path: Path) -> None:
    # plain chi2 above the band, the chi2 with the rig's covariance inside within it:
    # the push would go ahead, so more poses would only cost robot time
    upper = chi2_dof_upper(DOF)
    fit = saved_fit(2 * upper, 0.9)
    assert more_poses_reason(Journal(tmp_path), plan(), fit) is None  # type: ignore[arg-type]
    assert Journal(tmp_path).last_event("more_poses") is None
    # and above the band with it: grows, saying which chi2 it was
    reason = more_poses_reason(Journal(tmp_path / "b"), plan(), saved_fit(0.9, 2 * upper))  # type: ignore[arg-type]
    assert reason is not None and "with the camera calibration's covariance" in reason
