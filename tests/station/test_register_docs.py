"""docs/station.md's register map and reason codes are the ones the station serves."""

from __future__ import annotations

import re

from hostpc.station import registers as reg
from tests.station.conftest import REPO


def test_the_documented_register_map_is_the_served_one() -> None:
    text = (REPO / "docs" / "station.md").read_text()
    rows = re.findall(r"^\| (\d+)(?:-(\d+))? \| ([A-Z_]+) \|", text, re.M)
    documented = {name: int(first) for first, _, name in rows}
    served = {name: value for name, value in vars(reg).items()
              if name.isupper() and isinstance(value, int) and not name.endswith("_LENGTH")
              and (name == "RESULT_CODE" or not name.startswith(("N_", "RESULT_", "FLAG_")))}
    assert documented == served
    for first, last, name in rows:
        if last:
            length = getattr(reg, f"{name}_LENGTH", None)
            span = int(last) - int(first) + 1
            assert span in (2, length), (name, span)
    assert f"count {reg.N_REGISTERS}" in text


def test_the_documented_reason_codes_are_the_served_ones() -> None:
    text = " ".join((REPO / "docs" / "station.md").read_text().split())
    block = text[text.index("Reason codes (REASON_CODE"):]
    block = block[:block.index("## Config file")]
    documented = [int(n) for n in re.findall(r"(?:: |; )(\d+) [a-z]", block)]
    assert documented == [int(reason) for reason in reg.Reason]
