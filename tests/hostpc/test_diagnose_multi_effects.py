"""Two and three effects hidden at once (compliance + geometry; compliance + backlash +
thermal expansion while the arm warms up 8 K) on stereo_target and world_point (laser
tracker) data: the ladder ends with exactly the hidden effects, the final chi2/dof is in its
band with nothing significant left, the fitted sizes are within 3 sigma of the truth, and the
zero offsets end far closer to the truth than they started.

What is *not* true, measured (docs/diagnostics.md, "Several effects at once"): the offsets'
error in degrees does not fall at every step. A model that lacks one of the effects absorbs
part of it in the offsets; adding geometry first moves them further off (on every seed), and
on world_point no order of the three effects makes the first step lower it. What falls at
every step with compliance + geometry is the error in units of the offsets' own sigma.
"""

from __future__ import annotations

import pytest

from tests.hostpc.multi_effects import CASES, Outcome, hidden_effects, run_case

TWO, THREE = "compliance+geometry", "compliance+backlash+thermal"


def check(outcome: Outcome, case: str) -> None:
    ladder = outcome.diagnosis.ladder
    assert ladder is not None and not ladder[0].adequate
    final = ladder[-1]
    assert set(final.effects) - set(ladder[0].effects) == hidden_effects(CASES[case]), \
        outcome.line()
    assert final.adequate, outcome.line()  # chi2/dof in its band, nothing significant left
    assert final.check.adequacy.chi2_ok
    assert outcome.sizes, "no hidden size was identified"
    for name, (fitted, sigma, true) in outcome.sizes.items():
        assert abs(fitted - true) < 3 * sigma, (name, fitted, sigma, true)
    start, end = outcome.steps[0], outcome.steps[-1]
    assert end.offsets_error < start.offsets_error, outcome.line()
    assert end.offsets_z < min(4.0, start.offsets_z / 3), outcome.line()
    if case == TWO:  # in units of their sigma the offsets' error falls at every step
        z = [s.offsets_z for s in outcome.steps]
        assert all(b < a for a, b in zip(z, z[1:], strict=False)), outcome.line()


FAST = [("stereo_target", TWO, 1), ("stereo_target", THREE, 1), ("world_point", TWO, 1)]


@pytest.mark.parametrize(("method", "case", "seed"), FAST)
def test_hidden_effects_are_found_together(method: str, case: str, seed: int) -> None:
    check(run_case(method, case, seed), case)


def test_a_flexible_first_pick_is_dropped_again() -> None:
    """World_point seed 5: the first step takes transmission_harmonic (it mimics the sum of
    compliance and backlash); once those are in, the ladder drops it."""
    outcome = run_case("world_point", THREE, 5)
    check(outcome, THREE)
    assert outcome.steps[1].added == "transmission_harmonic"
    removed = [r for s in outcome.steps for r in s.removed]
    assert removed == ["transmission_harmonic"]
    assert "transmission_harmonic" not in outcome.diagnosis.ladder[-1].effects  # type: ignore[index]
    assert any("dropping transmission_harmonic" in a for a in outcome.diagnosis.advice)


# Two more seeds per case in CI; `python bench/bench_diagnose_multi.py` runs seeds 0-7 of
# every case (32 runs, all end with exactly the hidden effects; docs/diagnostics.md). Seed 2
# of stereo_target THREE fails the 3-sigma size check even for the true model fitted to the
# same data (backlash.b2 3.8 sigma off: a noise draw, not the ladder), so it is not used here.
SLOW = ([("stereo_target", TWO, s) for s in (0, 3)]
        + [("stereo_target", THREE, s) for s in (0, 3)]
        + [("world_point", TWO, s) for s in (0, 3)]
        + [("world_point", THREE, s) for s in (0, 3)])


@pytest.mark.slow
@pytest.mark.parametrize(("method", "case", "seed"), SLOW)
def test_hidden_effects_are_found_together_more_seeds(method: str, case: str,
                                                       seed: int) -> None:
    check(run_case(method, case, seed), case)
