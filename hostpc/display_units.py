"""The units a reader sees: SI values (docs/conventions.md) shown as mm, degrees and ppm at
the edges (CLI text, advice sentences). One table, no I/O: every layer may import it."""

from __future__ import annotations

import math

#: SI unit -> (display unit, factor from SI)
DISPLAY_UNITS = {
    "rad": ("deg", math.degrees(1.0)),
    "m": ("mm", 1e3),
    # a compliance is ~1e-4 deg per N m: per kN m it shows digits ("+0.1719", not "+0.0002")
    "rad/(N m)": ("deg/(kN m)", math.degrees(1.0) * 1e3),
    # a prismatic joint's compliance (m per N of the force along its axis): ~1e-6 m/N
    "m/N": ("mm/kN", 1e6),
    "1": ("ppm", 1e6),
}


def to_display(value: float, unit: str) -> tuple[float, str]:
    """(value in the display unit, display unit) of an SI value; other units unchanged."""
    shown, factor = DISPLAY_UNITS.get(unit, (unit, 1.0))
    return value * factor, shown


def quantity(value: float, unit: str, signed: bool = True) -> str:
    """A value in its display unit to 3 significant digits: "+0.186 mm", "+1200 ppm"
    (no exponent from 1e-3 to 1e5), "-0.0573 deg"; a unitless "" has no unit."""
    shown_value, shown = to_display(value, unit)
    sign = "+" if signed else ""
    if 1e3 <= abs(shown_value) < 1e5:
        text = f"{shown_value:{sign}.0f}"
    else:
        text = f"{shown_value:{sign}.3g}"
    return f"{text} {shown}" if shown else text
