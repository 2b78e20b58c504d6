"""The push guard's chi2 band with the head camera's calibration covariance inside
(hostpc.calibrate.push.adequacy_chi2, hostpc.fitting.shared_chi2; docs/vision.md 3.3)."""

from __future__ import annotations

import copy
from typing import Any

import numpy as np
import pytest

import hostpc
from hostpc.calibrate.push import adequacy_chi2, plan_push
from hostpc.dataset import dataset_from_dict
from hostpc.diagnostics.adequacy import chi2_dof_upper
from hostpc.errors import InputError
from hostpc.kinds.dual_loop.planning import plan_poses
from tests.hostpc.test_head_camera_uncertainty import world_documents


def _chi2_shared(result: Any) -> tuple[float, bool]:
    """(the chi2/dof the push guard tests, whether the shared error is inside)."""
    tested = adequacy_chi2(result)
    return tested.chi2_dof, tested.shared

def test_a_calibration_error_within_its_stated_covariance_does_not_refuse_the_push() -> None:
    """A humanoid world whose head camera calibration errs by 1 px (and says so): the
    plain chi2/dof is above the band (the old guard refused), the chi2 with the stated
    calibration covariance inside is not, and the push goes ahead. The same data with a
    calibration that claims to be exact is refused: the band still refuses what the stated
    covariances cannot explain."""
    document, _ = world_documents(1, plan_poses(40, np.random.default_rng(3)), 1.0)
    result = hostpc.fit(dataset_from_dict(document), cv_folds=0)
    band = chi2_dof_upper(result.dof)
    assert result.converged and result.chi2_dof > band
    tested, shared = _chi2_shared(result)
    assert shared and tested < band
    old = np.zeros(16)
    plan = plan_push(result, old, max_correction_deg=5.0)
    assert plan.refused is None and plan.chi2_dof_tested == tested

    exact = copy.deepcopy(document)
    block = exact["rig_uncertainty"]
    block["covariance"] = (np.asarray(block["covariance"]) * 1e-8).tolist()
    claimed = hostpc.fit(dataset_from_dict(exact), cv_folds=0)
    tested, shared = _chi2_shared(claimed)
    assert shared and tested > band
    refusal = plan_push(claimed, old, max_correction_deg=5.0).refused
    assert refusal is not None and "with the camera calibration's covariance" in refusal

    plain = copy.deepcopy(document)
    plain.pop("rig_uncertainty")
    without = hostpc.fit(dataset_from_dict(plain), cv_folds=0)
    assert _chi2_shared(without) == (without.chi2_dof, False)
    assert plan_push(without, old, max_correction_deg=5.0).chi2_dof_tested is None


def test_a_saved_fit_carries_the_chi2_the_push_tests() -> None:
    """`hostpc fit --json` writes the chi2/dof with the calibration covariance; the offline
    push (`hostpc push FIT.json`) tests that one, as the calibrate run does."""
    from hostpc.calibrate.offline_push import saved_fit_from_dict

    document, _ = world_documents(1, plan_poses(40, np.random.default_rng(3)), 1.0)
    result = hostpc.fit(dataset_from_dict(document), cv_folds=0)
    saved_document = result.to_dict()
    tested, _ = _chi2_shared(result)
    assert saved_document["chi2_dof_with_calibration"] == tested
    saved = saved_fit_from_dict(saved_document, "fit.json")
    assert saved.chi2_dof > chi2_dof_upper(saved.dof)
    plan = plan_push(saved, np.zeros(16), max_correction_deg=5.0)  # type: ignore[arg-type]
    assert plan.refused is None and plan.chi2_dof_tested == tested
    del saved_document["chi2_dof_with_calibration"]  # an older fit.json: the plain chi2
    older = saved_fit_from_dict(saved_document, "fit.json")
    assert plan_push(older, np.zeros(16), max_correction_deg=5.0).refused  # type: ignore[arg-type]
    # a hand-edited NaN would skip the chi2 check: one line instead
    saved_document["chi2_dof_with_calibration"] = float("nan")
    with pytest.raises(InputError, match="chi2_dof_with_calibration: expected a finite"):
        saved_fit_from_dict(saved_document, "fit.json")


def test_diagnose_judges_the_chi2_the_push_tests() -> None:
    """One adequacy rule: `hostpc diagnose`'s chi-square verdict is on the chi2 with the
    calibration inside when the dataset carries it (it judged the plain one: NOT adequate
    where the push went ahead)."""
    from hostpc.diagnostics.adequacy import assess, chi2_p_value

    document, _ = world_documents(1, plan_poses(40, np.random.default_rng(3)), 1.0)
    result = hostpc.fit(dataset_from_dict(document), cv_folds=0)
    tested, shared = _chi2_shared(result)
    assert shared and result.chi2_dof > chi2_dof_upper(result.dof) >= tested
    adequacy = assess(result, None)
    assert adequacy.chi2_dof_with_calibration == pytest.approx(tested, rel=1e-12)
    assert adequacy.chi2_ok
    assert adequacy.p_value == pytest.approx(chi2_p_value(tested * result.dof, result.dof))
    plain = copy.deepcopy(document)
    plain.pop("rig_uncertainty")
    without = assess(hostpc.fit(dataset_from_dict(plain), cv_folds=0), None)
    assert without.chi2_dof_with_calibration is None and not without.chi2_ok
