"""The advice on a "parameter differs per level" finding: its figures in the units a
reader sees (the CLI's display table: mm, deg, ppm, deg/(kN m)), and a level named only when
it stands out from the runner-up; level names quoted in the list of values."""

from __future__ import annotations

import math

import pytest

from hostpc.diagnostics.advice import group_sentence
from hostpc.diagnostics.interactions import Interaction
from hostpc.display_units import quantity


def _interaction(shifts: dict[str, float], unit: str = "m", parameter: str = "world.x",
                 variable: str = "marker") -> Interaction:
    return Interaction(parameter, variable, 40.0, 200.0, len(shifts) - 1, 1e-40, True,
                       "per level", True, unit=unit, level_shifts=tuple(shifts.items()))


@pytest.mark.parametrize(("value", "unit", "text"), [
    (3e-4, "m", "+0.3 mm"),
    (-math.radians(0.0123), "rad", "-0.0123 deg"),
    (1.2e-3, "1", "+1200 ppm"),
    (math.radians(2e-3), "rad/(N m)", "+2 deg/(kN m)"),
    (2e-3, "s", "+0.002 s"),
    (-0.5, "", "-0.5"),
])
def test_a_quantity_is_shown_in_the_display_unit(value: float, unit: str, text: str) -> None:
    assert quantity(value, unit) == text


def test_the_display_table_is_the_cli_one() -> None:
    from hostpc.cli import format as cli_format
    from hostpc.display_units import DISPLAY_UNITS
    assert cli_format.DISPLAY_UNITS is DISPLAY_UNITS
    assert cli_format.display(1.2e-3, "1") == ("+1200.0000", "ppm")


def test_a_level_that_stands_out_is_named() -> None:
    text = group_sentence(_interaction({"a": 1.2e-4, "b": -3e-4, "c": 1.8e-4}))
    assert text.startswith("the samples of marker b disagree with the others")
    assert "would be 'a' +0.12 mm, 'b' -0.3 mm, 'c' +0.18 mm" in text


def test_tied_levels_name_no_single_level() -> None:
    """4 markers, a and b off together: all four shifts are equally large."""
    text = group_sentence(_interaction({"a": 1e-4, "b": 1e-4, "c": -1e-4, "d": -1e-4}))
    assert "marker a disagrees" not in text and "the samples of marker a" not in text
    assert text.startswith("the samples of the markers disagree; no one marker stands out")
    assert "'a' +0.1 mm, 'b' +0.1 mm, 'c' -0.1 mm, 'd' -0.1 mm" in text
    near = group_sentence(_interaction({"a": 1.3e-4, "b": -1e-4, "c": -0.3e-4}))
    assert "no one marker stands out" in near  # 1.3 against 1.0: less than 1.5 times


def test_two_levels_give_their_difference_and_a_unitless_scale_is_in_ppm() -> None:
    text = group_sentence(_interaction({"left": -2e-6, "right": 2e-6}, unit="1",
                                       parameter="scale.s", variable="chain"))
    assert "the samples of chain left and chain right disagree" in text
    assert "'left' -2 ppm, 'right' +2 ppm" in text
    assert "a difference of -4 ppm (left - right)" in text


def test_many_levels_list_the_largest() -> None:
    shifts = {str(k): 1e-6 * (k % 3 - 1) for k in range(40)}
    shifts["17"] = 5e-5
    text = group_sentence(_interaction(shifts, variable="probe_group"))
    assert text.startswith("the samples of probe_group 17 disagree with the others")
    assert "'17' +0.05 mm" in text
    assert text.count("'") <= 2 * 8  # at most 8 levels listed
    assert "the other 32 probe_groups within 0.001 mm" in text
