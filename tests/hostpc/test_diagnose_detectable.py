"""What the plan can see: diagnose states, for each candidate, the smallest size the data
would find (80 % power at the candidates' threshold), in the effect's units and as a shift
of the measured points; an effect well above it is found, one well below it is not (the
40-world check is bench/bench_detectable.py)."""

from __future__ import annotations

import math

import pytest

from hostpc.diagnostics import DEFAULT_ALPHA, diagnose
from hostpc.diagnostics.candidates import candidate_effects, rank_candidates
from hostpc.diagnostics.detectable import (
    candidate_sizes,
    planned_sizes,
    power,
    required_noncentrality,
)
from hostpc.diagnostics.distributions import chi2_isf
from hostpc.fitting import fit
from hostpc.model.registry import available_effects
from tests.hostpc.diagnose_support import hidden_dataset


def test_the_noncentrality_gives_the_power() -> None:
    alpha = 1e-3
    lam = required_noncentrality(alpha, 0.8)
    assert power(lam, chi2_isf(alpha, 1)) == pytest.approx(0.8, abs=1e-6)
    # one degree of freedom: (z_{1-alpha/2} + z_{0.8})^2 = (3.29 + 0.84)^2 = 17.1
    assert lam == pytest.approx(17.1, rel=0.05)


def test_diagnose_states_what_these_poses_can_see() -> None:
    diagnosis = diagnose(hidden_dataset({}, seed=3).dataset)
    by_effect = {d.effect: d for d in diagnosis.detectable}
    assert set(by_effect) == {c.effect for c in diagnosis.check.candidates}
    depth = by_effect["depth_scale"]
    assert depth.parameter == "depth_scale.s" and 0 < depth.size < 0.1
    assert depth.shift > 0 and "would not be seen with these poses" in depth.sentence
    assert diagnosis.to_dict()["detectable"]


@pytest.mark.parametrize("seed", [101, 102])
def test_three_times_the_stated_size_is_found_and_a_third_is_not(seed: int) -> None:
    registry = available_effects()
    base = fit(hidden_dataset({}, seed=seed).dataset, cv_folds=0)
    names = candidate_effects(base.problem, registry)
    stated = next(s for s in candidate_sizes(base, registry, names, DEFAULT_ALPHA)
                  if s.effect == "depth_scale")
    assert math.isfinite(stated.size)
    for factor, expected in ((3.0, True), (1 / 3, False)):
        dataset = hidden_dataset({"depth_scale.s": factor * stated.size}, seed=seed).dataset
        extended = fit(dataset, cv_folds=0)
        ranked, _ = rank_candidates(extended, registry, names, alpha=DEFAULT_ALPHA,
                                    cv_folds=3, loss="linear")
        assert any(c.effect == "depth_scale" and c.significant for c in ranked) is expected


def test_the_plan_states_the_sizes_before_measuring() -> None:
    """From the design alone (the planned poses' nominal predictions and stated noise) the
    sizes are those the data of the same poses give after measuring (noise at its stated
    level): planning and diagnosis agree on what the poses can see."""
    dataset = hidden_dataset({}, seed=3).dataset
    base = fit(dataset, cv_folds=0)
    registry = available_effects()
    names = candidate_effects(base.problem, registry)
    after = {s.effect: s for s in candidate_sizes(base, registry, names, DEFAULT_ALPHA)}
    before = {s.effect: s for s in planned_sizes(dataset, None, (), DEFAULT_ALPHA)}
    assert set(before) == set(after)
    noise = math.sqrt(max(base.chi2_dof, 1.0))
    for name, planned in before.items():  # the best-seen parameter's shift (near ties
        # between parameters may pick another one of the effect: its shift is close)
        assert math.isfinite(after[name].shift) and math.isfinite(planned.shift)
        assert planned.shift * noise == pytest.approx(after[name].shift, rel=0.2), name
        if planned.parameter == after[name].parameter:
            assert planned.size * noise == pytest.approx(after[name].size, rel=0.1), name


def test_an_implausible_size_is_not_detectable_and_states_its_threshold() -> None:
    """Six planned poses of the hidden-compliance example: joint 6 carries almost no gravity
    torque, so its compliance would show only at 6.8e13 rad/(N m) (a shift of 0.28 mm:
    the measured points move by the noise, whatever the size). The plan line printed that
    size as joint compliance's best-seen; now it names the best-seen plausible parameter
    (joint 2's), and a size beyond PLAUSIBLE_SIZE reads as not detectable, with the
    threshold."""
    from pathlib import Path

    import numpy as np

    from hostpc.dataset import load_dataset
    from hostpc.diagnostics.detectable import PLAUSIBLE_SIZE, DetectableSize

    example = Path(__file__).parents[2] / "examples" / "ur5e_stereo_hidden_compliance.json"
    dataset = load_dataset(example)
    design = dataset.with_samples(dataset.samples.subset(np.arange(6)))
    planned = {s.effect: s for s in planned_sizes(design, None, (), DEFAULT_ALPHA)}
    compliance = planned["joint_compliance"]
    assert compliance.parameter != "joint_compliance.c6"
    assert compliance.seen and compliance.size <= PLAUSIBLE_SIZE["rad/(N m)"]
    for size in planned.values():
        assert size.seen or "not detectable with these poses" in size.short
        assert "e+" not in size.short, size.short  # no 6e+12, no 3.2e+02 um
    absurd = DetectableSize("joint_compliance", "joint_compliance.c6", 6.8e13, "rad/(N m)",
                            2.8e-4)
    assert not absurd.seen
    assert absurd.short == ("joint_compliance.c6 not detectable with these poses (only "
                            "above 0.001 rad/(N m), more than any real robot's)")
    assert absurd.sentence.startswith("joint_compliance.c6 is not detectable with these poses")
