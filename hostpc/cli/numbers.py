"""Argument types for numeric command-line options: finite and within a range, or refused.

    parser.add_argument("--timeout", type=finite(above=0.0, most=3600.0), default=5.0)
    parser.add_argument("--cv-folds", type=CV_FOLDS, default=5)

A bad value is refused by the argument parser itself, as one line and exit code 2
(`hostpc.cli.main` makes argparse errors one line): ``hostpc fit: error: argument
--cv-folds: expected 0 or an integer from 2 to 1000, got '1'``. `nan`, `inf` and `-inf`
are never accepted.
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable


def _describe(above: float | None, least: float | None, below: float | None,
              most: float | None) -> str:
    parts = []
    if above is not None:
        parts.append(f"> {above:g}")
    if least is not None:
        parts.append(f">= {least:g}")
    if below is not None:
        parts.append(f"< {below:g}")
    if most is not None:
        parts.append(f"<= {most:g}")
    return "a finite number" + (" " + " and ".join(parts) if parts else "")


def finite(*, above: float | None = None, least: float | None = None,
           below: float | None = None, most: float | None = None) -> Callable[[str], float]:
    """An argparse type: a finite float with the given bounds (open: above/below; closed:
    least/most)."""
    wanted = _describe(above, least, below, most)

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {wanted}, got {text!r}") from None
        if not math.isfinite(value) or (
            (above is not None and not value > above)
            or (least is not None and not value >= least)
            or (below is not None and not value < below)
            or (most is not None and not value <= most)
        ):
            raise argparse.ArgumentTypeError(f"expected {wanted}, got {text!r}")
        return value

    parse.__name__ = "number"  # argparse names the type in some messages
    return parse


def integer(*, least: int | None = None, most: int | None = None,
            also: tuple[int, ...] = ()) -> Callable[[str], int]:
    """An argparse type: an integer in [least, most] (or one of `also`)."""
    span = (f"from {least} to {most}" if least is not None and most is not None
            else f">= {least}" if least is not None else f"<= {most}" if most is not None
            else "")
    wanted = " or ".join([str(v) for v in also] + [f"an integer {span}".strip()])

    def parse(text: str) -> int:
        try:
            value = int(text, 10)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {wanted}, got {text!r}") from None
        if value in also:
            return value
        if (least is not None and value < least) or (most is not None and value > most):
            raise argparse.ArgumentTypeError(f"expected {wanted}, got {text!r}")
        return value

    parse.__name__ = "integer"
    return parse


CV_FOLDS = integer(least=2, most=1000, also=(0,))
"""--cv-folds: 0 (no cross-validation) or 2..1000 folds."""
TIMEOUT_S = finite(above=0.0, most=86400.0)
"""--timeout: seconds per request, positive, at most a day."""
PROBABILITY = finite(above=0.0, below=1.0)
"""A significance level or probability strictly between 0 and 1."""
