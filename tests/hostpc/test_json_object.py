"""``dumps_indented`` writes what ``json.dumps(value, indent=2, allow_nan=False)`` writes,
character for character (the `--json` output of `hostpc diagnose` and `hostpc fit`), and
fails as it fails."""

from __future__ import annotations

import json
import math
import random
from collections import OrderedDict
from enum import IntEnum
from pathlib import Path

import numpy as np
import pytest

from hostpc.diagnostics import diagnose
from hostpc.json_object import dumps_indented

ROOT = Path(__file__).resolve().parents[2]


def _expected(value: object) -> str:
    return json.dumps(value, indent=2, allow_nan=False)


class _Level(IntEnum):
    LOW = 1


def _random_value(rng: random.Random, depth: int) -> object:
    kind = rng.randrange(9 if depth < 4 else 6)
    if kind == 0:
        return rng.choice([None, True, False])
    if kind == 1:
        return rng.randrange(-10**20, 10**20)
    if kind == 2:
        return rng.choice([rng.uniform(-1e3, 1e3), rng.random() * 10.0 ** rng.randrange(-320, 308),
                           -0.0, 0.0, 1e16, 5e-324])
    if kind == 3:
        letters = 'ab"\\\n\t\u00e9\u4e2d\U0001f600/\x00'
        return "".join(rng.choice(letters) for _ in range(rng.randrange(6)))
    if kind == 4:
        return float(np.float64(rng.uniform(-1.0, 1.0)))
    if kind == 5:
        return rng.choice([np.float64(rng.gauss(0.0, 1.0)), _Level.LOW, ""])
    items = [_random_value(rng, depth + 1) for _ in range(rng.randrange(4))]
    if kind == 6:
        return items
    if kind == 7:
        return tuple(items)
    return {f"k{i}\u00fc\"": item for i, item in enumerate(items)}


def test_same_text_as_json_for_random_documents() -> None:
    rng = random.Random(7)
    for _ in range(400):
        value = _random_value(rng, 0)
        assert dumps_indented(value) == _expected(value)


def test_same_text_for_the_ladder_document() -> None:
    document = diagnose(ROOT / "examples" / "ur5e_stereo.json", ladder=True).to_dict()
    assert dumps_indented(document) == _expected(document)


@pytest.mark.parametrize("value", [
    {1: "a", 2.5: "b", None: 1, False: 2},  # keys json converts
    OrderedDict([("b", 1), ("a", [])]),
    {"nested": [[], {}, [[{}]]]},
    "plain",
    [1.0, -0.0, 1e-7, 123456789.0, 10**30],
])
def test_same_text_for_edge_cases(value: object) -> None:
    assert dumps_indented(value) == _expected(value)


@pytest.mark.parametrize("value", [
    {"a": math.nan}, [math.inf], {"a": [-math.inf]}, {"a": object()}, {(1, 2): 3},
])
def test_fails_as_json_fails(value: object) -> None:
    with pytest.raises((ValueError, TypeError)) as expected:
        _expected(value)
    with pytest.raises(type(expected.value), match=str(expected.value)[:30].replace("(", r"\(")):
        dumps_indented(value)


def test_a_cycle_fails_as_json_fails() -> None:
    cycle: list[object] = []
    cycle.append(cycle)
    with pytest.raises(ValueError, match="Circular reference detected"):
        dumps_indented(cycle)
