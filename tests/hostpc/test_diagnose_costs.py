"""What a candidate costs: a candidate is significant only if it also predicts held-out
samples better, one that makes an identifiable parameter unidentifiable is never taken
silently, and the search lists neither held parameters nor one combination twice."""

from __future__ import annotations

import numpy as np

from hostpc.cli.diagnose import format_diagnosis
from hostpc.diagnostics import diagnose
from hostpc.diagnostics.candidates import try_candidate
from hostpc.diagnostics.interactions import search_interactions
from hostpc.diagnostics.pipeline import variables_of
from hostpc.fitting import fit
from hostpc.model.effects import JointCompliance
from hostpc.synthesize import random_truth, synthesize_stereo_target
from tests.hostpc.diagnose_support import hidden_dataset


def test_significant_needs_a_better_held_out_prediction() -> None:
    synthetic = hidden_dataset({"joint_compliance.c2": 2e-5}, seed=6, n_samples=80)
    base = fit(synthetic.dataset, cv_folds=0)
    honest = try_candidate(base, JointCompliance(), cv_folds=3, loss="linear",
                           threshold=1e-3, base_cv=10.0)
    assert honest.significant and honest.not_taken is None and honest.taken
    assert honest.cv_whitened_rms is not None
    # the same candidate against a current model that (pretend) predicts perfectly
    worse = try_candidate(base, JointCompliance(), cv_folds=3, loss="linear",
                          threshold=1e-3, base_cv=0.0)
    assert worse.p_value is not None and worse.p_value < 1e-3
    assert not worse.significant and not worse.taken
    assert worse.not_taken is not None
    assert worse.not_taken.startswith("significant in-sample") and "held-out" in worse.not_taken


def test_backlash_that_hides_a_zero_offset_is_not_taken_silently() -> None:
    """Joint 4 always arrives from the same side: its offset and its backlash are one
    number. Adding backlash (significant: joints 2 and 3 have some) would drop joint 4's
    correction; the ranking, the advice, the text and the ladder say so instead."""
    truth = random_truth(np.random.default_rng(3))
    truth.update({"backlash.b2": 1.5e-4, "backlash.b3": 1.5e-4})
    approach = np.array(synthesize_stereo_target(truth, seed=3).dataset.samples.approach)
    approach[:, 3] = 1.0
    dataset = synthesize_stereo_target(truth, seed=3, approach=approach).dataset
    diagnosis = diagnose(dataset, ladder=True, candidates=["backlash", "encoder_scale"])
    backlash = next(c for c in diagnosis.candidates if c.effect == "backlash")
    assert backlash.significant and not backlash.taken
    assert backlash.unidentifiable == ("joint_offsets.q4",)
    assert backlash.not_taken is not None
    assert "approach joint 4 from both sides" in backlash.not_taken
    assert "--hold backlash.b4" in backlash.not_taken
    assert diagnosis.check.best_candidate is None
    assert diagnosis.ladder is not None and [s.added for s in diagnosis.ladder] == [None]
    assert diagnosis.ladder_stop is not None and "joint_offsets.q4" in diagnosis.ladder_stop
    assert any("makes joint_offsets.q4 unidentifiable" in s for s in diagnosis.advice)
    assert "not taken: adding backlash makes joint_offsets.q4" in format_diagnosis(diagnosis)
    assert backlash.to_dict()["unidentifiable"] == ["joint_offsets.q4"]


def test_search_skips_held_parameters_and_merges_one_combination() -> None:
    synthetic = hidden_dataset({"joint_compliance.c2": 2e-5}, seed=6, n_samples=80)
    base = fit(synthetic.dataset, cv_folds=0)
    held = {n for n, f in zip(base.names, base.fixed, strict=True) if f}
    assert held  # this design cannot see joint 1's and joint 6's zero from the rest
    found, n_tests = search_interactions(base, variables_of(base), alpha=1e-3)
    assert n_tests == len(found)
    assert not any(i.parameter in held or set(i.equivalent) & held for i in found)
    # the UR's parallel axes 2, 3, 4: d2, d3 and d4 move the flange the same way
    merged = [i for i in found if i.parameter == "geometry.d2"]
    assert merged and all(i.equivalent == ("geometry.d3", "geometry.d4") for i in merged)
    assert not any(i.parameter in ("geometry.d3", "geometry.d4") for i in found)
    assert "(or equally geometry.d3, geometry.d4)" in merged[0].sentence
