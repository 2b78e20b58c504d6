"""Per-chain variables are tested on the samples where they exist: a hidden effect in one
arm of a dual_loop dataset is found by the search and the binned residuals."""

from __future__ import annotations

import numpy as np
import pytest

import hostpc
from hostpc.dataset import Dataset
from hostpc.diagnostics.interactions import modulators, search_interactions
from hostpc.diagnostics.pipeline import variables_of
from hostpc.diagnostics.residual_analysis import analyse_residuals, usable_variables
from hostpc.fitting import fit
from hostpc.kinds.dual_loop.planning import plan_poses
from hostpc.kinds.dual_loop.synthesize import synthesize_dual_loop
from tests.hostpc.diagnose_support import coupled_dual_loop

HIDDEN = {"joint_coupling.left.k4_3": 4e-3}  # the left elbow reads off by 4e-3 rad per rad


@pytest.fixture(scope="module")
def coupled() -> Dataset:
    return coupled_dual_loop(HIDDEN)


def test_per_chain_variables_are_kept_with_their_missing_samples() -> None:
    left = np.array([0.1, np.nan, 0.3, np.nan, 0.2, 0.5, np.nan, 0.4, 0.0, 0.6, 0.7, np.nan])
    usable = usable_variables({"left.q3": left, "few": np.r_[1.0, 2.0, [np.nan] * 10]})
    assert list(usable) == ["left.q3"]  # defined on 8 samples: tested; on 2: not
    F, basis = modulators("left.q3", left)
    assert F.shape == (12, 3) and basis == "linear+harmonic"
    assert np.all(F[np.isnan(left)] == 0.0)  # no variation where the variable does not exist
    assert np.allclose(F[~np.isnan(left)].mean(axis=0), 0.0)


def test_hidden_left_elbow_coupling_is_found_on_the_left_samples(coupled: Dataset) -> None:
    base = fit(coupled, cv_folds=0)
    variables = variables_of(base)
    assert np.any(np.isnan(variables["left.q3"]))  # NaN on the right arm's samples
    found, _ = search_interactions(base, variables, alpha=1e-3)
    top = found[0]
    assert (top.parameter, top.variable) == ("joint_offsets.left.q4", "left.q3")
    assert top.significant
    assert not any(i.significant for i in found if i.variable.startswith("right."))
    analysis = analyse_residuals(base.residuals_raw, base.residuals_whitened, variables,
                                 alpha=1e-3)
    left_q3 = next(p for p in analysis.patterns if p.variable == "left.q3")
    assert left_q3.significant
    assert left_q3.counts.sum() == np.count_nonzero(coupled.samples.chain == "left")


def test_elbow_coupling_is_closed_by_a_generated_effect(coupled: Dataset) -> None:
    """No built-in effect couples the elbow: the ladder builds "joint_offsets.left.q4 linear
    in left.q3" itself (auto_effects) and the model becomes adequate."""
    diagnosis = hostpc.diagnose(coupled, ladder=True,
                                candidates=["joint_coupling", "encoder_scale", "backlash"])
    assert not diagnosis.adequate and diagnosis.ladder is not None
    assert [s.added for s in diagnosis.ladder] == [None, "left_q4_with_left_q3"]
    assert diagnosis.ladder[-1].adequate


def test_wrist_coupling_in_one_arm_is_the_built_in_effect() -> None:
    dataset = synthesize_dual_loop({"joint_coupling.left.k6_5": 2e-2},
                                   plan_poses(50, np.random.default_rng(1)), seed=2)
    diagnosis = hostpc.diagnose(dataset, ladder=True,
                                candidates=["joint_coupling", "encoder_scale", "backlash"])
    assert diagnosis.candidates[0].effect == "joint_coupling"
    assert diagnosis.candidates[0].selected[0] == "joint_coupling.left.k6_5"
    assert diagnosis.ladder is not None
    assert [s.added for s in diagnosis.ladder] == [None, "joint_coupling"]
    assert diagnosis.ladder[-1].adequate
    assert any("joint_coupling" in sentence for sentence in diagnosis.advice)
