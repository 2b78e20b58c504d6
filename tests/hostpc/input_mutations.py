"""Mutations of valid input files for the fuzz tests (test_mutated_inputs.py).

Two families, both driven by a seeded numpy Generator so a failure is reproducible from
its index:
- structural (JSON documents): one value somewhere in the tree replaced by a type swap
  (number -> string, bool -> "false"), null, a huge or non-finite number (NaN, Infinity
  literals), nested garbage, a list one shorter or longer, a deleted or duplicated key, a
  very deep nesting;
- textual (any file): bytes flipped, inserted or cut, the file truncated or emptied.
"""

from __future__ import annotations

import copy
import json
from typing import Any

import numpy as np

DUPLICATE = "__duplicate_key__"
DEEP = "__deeply_nested__"


def _paths(value: Any, path: tuple[Any, ...] = ()) -> list[tuple[Any, ...]]:
    """Every path into a JSON tree (the root excluded), depth first."""
    found: list[tuple[Any, ...]] = []
    items: list[tuple[Any, Any]] = (list(value.items()) if isinstance(value, dict)
                                    else list(enumerate(value)) if isinstance(value, list)
                                    else [])
    for key, child in items:
        found.append((*path, key))
        found.extend(_paths(child, (*path, key)))
    return found


def _get(document: Any, path: tuple[Any, ...]) -> Any:
    for key in path:
        document = document[key]
    return document


def _replacement(old: Any, rng: np.random.Generator) -> Any:
    """A damaged stand-in for ``old``."""
    choices: list[Any] = [
        None, "false", "true", "0.1", "", "NaN", float("nan"), float("inf"), -float("inf"),
        1e308, -1e308, 1e200, 0, -1, True, False, {"garbage": [[[]]]}, [], {}, [1, "x", None],
    ]
    if isinstance(old, bool):
        choices += [str(old).lower(), int(old), not old]
    elif isinstance(old, int | float):
        choices += [str(old), old * 1e6, -old, old + 1, 10 ** 30, 0.0]
    elif isinstance(old, str):
        choices += [old + "x", old[:-1], 3.5, [old]]
    elif isinstance(old, list):
        choices += [old[:-1], old + old[-1:], old[:1], [old]]
    elif isinstance(old, dict):
        choices += [list(old.values())[:2]]
    return choices[int(rng.integers(len(choices)))]


def mutate_document(document: Any, rng: np.random.Generator) -> str:
    """A JSON text of ``document`` with one structural damage (the text may use the NaN /
    Infinity literals and duplicated keys, as a hand-edited file can)."""
    damaged = copy.deepcopy(document)
    paths = _paths(damaged)
    path = paths[int(rng.integers(len(paths)))]
    parent, key = _get(damaged, path[:-1]), path[-1]
    action = int(rng.integers(10))
    if action == 0 and isinstance(parent, dict):
        del parent[key]
    elif action == 1 and isinstance(parent, dict):
        parent[DUPLICATE] = _replacement(parent[key], rng)
        text = json.dumps(damaged)
        return text.replace(json.dumps(DUPLICATE), json.dumps(key), 1)
    elif action == 2:
        parent[key] = DEEP
        return json.dumps(damaged).replace(json.dumps(DEEP), "[" * 3000 + "]" * 3000, 1)
    elif action == 3 and isinstance(parent[key], list) and parent[key]:
        parent[key] = parent[key][: int(rng.integers(len(parent[key])))]
    else:
        parent[key] = _replacement(parent[key], rng)
    if action == 4:
        return json.dumps(damaged).replace("1e+308", "1" + "0" * 5000, 1)
    return json.dumps(damaged)


def mutate_bytes(data: bytes, rng: np.random.Generator) -> bytes:
    """``data`` with bytes flipped, inserted, cut or the whole truncated."""
    buffer = bytearray(data)
    action = int(rng.integers(6))
    if action == 0:
        return bytes(buffer[: int(rng.integers(len(buffer) + 1))])
    if action == 1:
        return b""
    for _ in range(int(rng.integers(1, 9))):
        position = int(rng.integers(len(buffer))) if buffer else 0
        if action == 2 and buffer:
            buffer[position] ^= 1 << int(rng.integers(8))
        elif action == 3:
            buffer[position:position] = bytes(rng.integers(0, 256, int(rng.integers(1, 5)),
                                                           dtype=np.uint8))
        elif action == 4:
            del buffer[position: position + int(rng.integers(1, 40))]
        else:
            junk = rng.choice(list(b'0123456789-.e"{}[],: \n\x00\xff'),
                              int(rng.integers(1, 6)))
            buffer[position: position + len(junk)] = bytes(junk.astype(np.uint8))
    return bytes(buffer)


def mutate(document: Any | None, text: bytes, rng: np.random.Generator) -> bytes:
    """One damaged file: structural for a JSON document (two in three), else textual."""
    if document is not None and rng.random() < 2 / 3:
        return mutate_document(document, rng).encode()
    return mutate_bytes(text, rng)


CELL_VALUES = ("nan", "inf", "-inf", "1e308", "1e200", "", "abc", "0x10", "1,5", '"', "true",
               "1" + "0" * 400, "-0", "1e-320")


def mutate_csv(text: str, rng: np.random.Generator) -> bytes:
    """A CSV with one cell replaced, a row cut short or lengthened, or a header renamed."""
    lines = text.splitlines()
    row = int(rng.integers(len(lines)))
    cells = lines[row].split(",")
    action = int(rng.integers(4))
    if action == 0:
        cells = cells[: int(rng.integers(len(cells)))]
    elif action == 1:
        cells.append(CELL_VALUES[int(rng.integers(len(CELL_VALUES)))])
    else:
        cells[int(rng.integers(len(cells)))] = CELL_VALUES[int(rng.integers(len(CELL_VALUES)))]
    lines[row] = ",".join(cells)
    return ("\n".join(lines) + "\n").encode()


ATTRIBUTE_VALUES = ("1e200 0 0", "0 0 1e200", "nan 0 0", "inf 0 0", "", "a b c", "1 2",
                    "1 2 3 4", "0 0 0", "-1e6 0 0", "1e-300 1e-300 1e-300", "1e308 1e308 0")


def mutate_urdf(text: str, rng: np.random.Generator) -> bytes:
    """A URDF with one attribute value (xyz, rpy, axis, mass, limit, link name) damaged."""
    import re

    spans = [m.span(1) for m in re.finditer(r'="([^"]*)"', text)]
    start, end = spans[int(rng.integers(len(spans)))]
    value = ATTRIBUTE_VALUES[int(rng.integers(len(ATTRIBUTE_VALUES)))]
    return (text[:start] + value + text[end:]).encode()
