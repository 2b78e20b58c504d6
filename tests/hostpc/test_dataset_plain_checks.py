"""The plain checks of ``hostpc.dataset.schema`` (a well-formed file is read without
pydantic) accept exactly what the pydantic models accept and return what they return.

Every value a reader hands to a check (the document head, each frame, each sample field as a
column) of the good documents, of every broken document of ``test_dataset_errors`` and of
its fuzzed ones goes to both: the same result, or the same one-line error (the plain path
hands any value it cannot vouch for to the models, so their message is the one shown)."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from pydantic import BaseModel

from hostpc.dataset import schema, schema_models
from hostpc.dataset.schema import FieldError
from tests.hostpc.test_dataset_errors import BASES, CASES, mutated, mutated_documents

ROOT = Path(__file__).resolve().parents[2]
EXAMPLES = sorted(path for path in (ROOT / "examples").glob("*.json")
                  if "zerocal-dataset/1" in path.read_text(encoding="utf-8"))
COLUMN_TYPES = (float, str, list[float], list[list[float]], list[list[list[float]]])


def _plain(value: Any) -> Any:
    """A model or a plain record as nested dicts; numbers with their type."""
    if isinstance(value, BaseModel):
        return {name: _plain(getattr(value, name)) for name in type(value).model_fields}
    if isinstance(value, SimpleNamespace):
        return {name: _plain(item) for name, item in vars(value).items()}
    if isinstance(value, dict):
        return {key: _plain(item) for key, item in value.items()}
    if isinstance(value, list):
        return [_plain(item) for item in value]
    return (type(value), value)


def _outcome(check: Callable[[], Any]) -> tuple[str, Any]:
    try:
        return "ok", _plain(check())
    except FieldError as exc:
        return "error", str(exc)


def _compare(plain: Callable[[], Any], model: Callable[[], Any]) -> bool:
    """Both give the same; True where the plain check accepted the value itself."""
    got = _outcome(plain)
    assert got == _outcome(model)
    return got[0] == "ok" and not isinstance(plain(), BaseModel)


def compare_document(doc: Any) -> int:
    """Compare every check the reader makes of ``doc``; how many the plain path took."""
    try:
        doc = schema.normalize(doc)
    except FieldError:
        return 0
    if not isinstance(doc, dict):
        return 0
    taken = 0
    for document in (doc, {**doc, "samples": []}):  # by samples, by columns
        taken += _compare(lambda d=document: schema.validate_document(d),
                          lambda d=document: schema_models.validate(
                              schema_models.DocumentSchema, d))
    frames = doc.get("frames")
    for name, value in (frames.items() if isinstance(frames, dict) else ()):
        loc = ("frames", name)
        checks = ((schema.validate_frame_pose, schema_models.FramePoseSchema),
                  (schema.validate_vec3, schema_models.Vec3),
                  (schema.validate_points, dict[str, schema_models.Vec3]))
        for check, kind in checks:
            taken += _compare(lambda c=check, v=value, at=loc: c(v, at),
                              lambda k=kind, v=value, at=loc: schema_models.validate(k, v, at))
    samples = doc.get("samples")
    if isinstance(samples, list) and all(isinstance(s, dict) for s in samples):
        for name in {key for sample in samples for key in sample}:
            column = [sample.get(name) for sample in samples]
            for kind in COLUMN_TYPES:
                taken += _compare(lambda k=kind, c=column: schema.validate(k, c),
                                  lambda k=kind, c=column: schema_models.validate(k, c))
            for value in column:
                for kind in COLUMN_TYPES:
                    taken += _compare(lambda k=kind, v=value: schema.validate(k, v),
                                      lambda k=kind, v=value: schema_models.validate(k, v))
    return taken


def test_the_field_lists_are_the_models_fields() -> None:
    assert tuple(schema_models.SampleSchema.model_fields) == schema.SAMPLE_FIELDS
    assert tuple(schema_models.DocumentSchema.model_fields) == schema.DOCUMENT_FIELDS


@pytest.mark.parametrize("path", EXAMPLES, ids=[p.name for p in EXAMPLES])
def test_examples_are_read_plainly_and_alike(path: Path) -> None:
    doc = json.loads(path.read_text(encoding="utf-8"))
    assert isinstance(schema.validate_document({**doc, "samples": []}), SimpleNamespace)
    assert compare_document(doc) > 10


@pytest.mark.parametrize("base", sorted(BASES))
def test_good_documents_alike(base: str) -> None:
    assert compare_document(BASES[base]()) > 10


@pytest.mark.parametrize("case", CASES, ids=[c[0] for c in CASES])
def test_broken_documents_alike(case: tuple[str, str, list[Any], str]) -> None:
    _, base, changes, _ = case
    compare_document(mutated(base, *changes))


@pytest.mark.parametrize("value", [
    True, None, "1", 2**60, 1, 1.5, [1, True], [[1.0], "x"], {"xyz": [0, 0, 0]},
    {"xyz": [0, 0, 0], "rpy": [0, 0]}, {"xyz": [0, 0, 0], "rpy": [0, 0, 0], "z": 1},
    {"a": [1, 2, 3], "b": [1, 2]}, {"format": "zerocal-dataset/1", "method": "x",
    "robot": {"name": "ur5e", "urdf": "a"}, "frames": {}, "samples": []},
])
def test_odd_values_alike(value: Any) -> None:
    doc = mutated("stereo", (("frames", "camera"), value), (("units",), value),
                  (("known",), value), (("robot",), value))
    compare_document(doc)
    compare_document(value)


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(mutated_documents())
def test_fuzzed_documents_alike(doc: dict[str, Any]) -> None:
    compare_document(doc)
