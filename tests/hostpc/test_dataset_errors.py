"""Dataset files fed broken input: every failure is one DatasetError line naming the field."""

from __future__ import annotations

import copy
import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hostpc.dataset import dataset_from_dict, dataset_to_dict, load_dataset, save_dataset
from hostpc.errors import DatasetError

_COV = [[2.2e-9, 0.0, 0.0], [0.0, 2.2e-9, 0.0], [0.0, 0.0, 7.3e-8]]


def stereo() -> dict[str, Any]:
    return {
        "format": "zerocal-dataset/1",
        "method": "stereo_target",
        "units": {"length": "m", "angle": "rad", "time": "s"},
        "robot": {"name": "ur5e"},
        "frames": {
            "tool": {"xyz": [0.0, 0.045, 0.06], "rpy": [0.0, 0.0, 1.5708]},
            "target": [0.45, 0.15, 0.02],
        },
        "known": ["tool", "target"],
        "samples": [
            {
                "q": [0.84, -0.39, -2.34, 2.13, -1.40, 1.26 + i],
                "p": [-0.0492, 0.0272, 0.4745],
                "cov": copy.deepcopy(_COV),
                "t": 21.27 + i,
                "approach": [-1, 1, 1, 1, -1, 1],
                "extra": {"gain": 1.5},
                "uv": [[640.0, 480.0], [600.0, 480.0]],
            }
            for i in range(4)
        ],
    }


def sphere() -> dict[str, Any]:
    return {
        "format": "zerocal-dataset/1",
        "method": "sphere_probe",
        "robot": {
            "convention": "dh",
            "joints": [{"a": 0.1 * i, "alpha": 0.5, "d": 0.2, "theta": 0.0} for i in range(6)],
            "mass": [1.0] * 6,
            "com": [[0.0, 0.0, 0.1]] * 6,
        },
        "frames": {"tool": {"xyz": [0, 0, 0.1]}, "sphere": {"center": [1, 0, 0], "radius": 0.01}},
        "probe": {"stylus_radius": 0.001},
        "samples": [
            {"q": [0.1 * i, 0.2, 0.3, 0.4, 0.5, 0.6], "sigma": 1e-6, "group": i // 2, "speed": 0.01}
            for i in range(4)
        ],
    }


def dual() -> dict[str, Any]:
    pose = {"xyz": [0.0, 0.0, 0.0], "rpy": [0.0, 0.0, 0.0]}
    return {
        "format": "zerocal-dataset/1",
        "method": "dual_loop",
        "robot": {"name": "humanoid_upper"},
        "frames": {
            "camera": dict(pose),
            "left_base": dict(pose),
            "right_base": dict(pose),
            "left_target": [0.0, 0.0, 0.05],
            "right_target": [0.0, 0.0, 0.05],
        },
        "samples": [
            {
                "chain": ["left", "right"][i % 2],
                "q_head": [0.1, 0.2],
                "q_arm": [0.1 * i] * (7 if i % 2 == 0 else 6),
                "p": [0.1, 0.0, 0.5],
                "sigma": 1e-4,
            }
            for i in range(4)
        ],
    }


BASES: dict[str, Callable[[], dict[str, Any]]] = {
    "stereo": stereo,
    "sphere": sphere,
    "dual": dual,
}
DELETE = object()


def mutated(base: str, *changes: tuple[tuple[Any, ...], Any]) -> dict[str, Any]:
    """The base document with ``value`` put at each ``path`` (DELETE removes the key)."""
    doc = BASES[base]()
    for path, value in changes:
        parent = doc
        for key in path[:-1]:
            parent = parent[key]
        if value is DELETE:
            del parent[path[-1]]
        else:
            parent[path[-1]] = value
    return doc


def assert_one_line_error(exc: DatasetError, source: str, expected: str) -> None:
    message = str(exc)
    assert message.startswith(f"{source}: "), message
    assert expected in message, message
    assert "\n" not in message, message
    assert "pydantic" not in message.lower() and "validation error" not in message, message


def test_base_documents_are_valid() -> None:
    for make in BASES.values():
        dataset_from_dict(make())


S0, S1, S2, S3 = (("samples", i) for i in range(4))
NOT_PD = [[1e-8, 2e-8, 0.0], [2e-8, 1e-8, 0.0], [0.0, 0.0, 1e-8]]
ASYMMETRIC = [[1e-8, 5e-9, 0.0], [0.0, 1e-8, 0.0], [0.0, 0.0, 1e-8]]

CASES: list[tuple[str, str, list[tuple[tuple[Any, ...], Any]], str]] = [
    # (id, base, changes, expected text)
    ("format", "stereo", [(("format",), "foo")], "format: expected 'zerocal-dataset/1', got 'foo'"),
    ("format-missing", "stereo", [(("format",), DELETE)], "format: required field missing"),
    ("format-v2", "sphere", [(("format",), "zerocal-dataset/2")], "format: expected"),
    ("method", "stereo", [(("method",), "laser")], "method: unknown method 'laser'"),
    ("method-missing", "dual", [(("method",), DELETE)], "method: required field missing"),
    (
        "joint-count",
        "stereo",
        [((*S0, "q"), [0.1] * 5)],
        "samples[0].q: expected 6 joint angles for robot 'ur5e', got 5",
    ),
    (
        "joint-count-explicit",
        "sphere",
        [((*S2, "q"), [0.1] * 7)],
        "samples[2].q: expected 6 joint angles",
    ),
    ("robot-unknown", "stereo", [(("robot", "name"), "nosuch")], "robot.name: unknown robot"),
    ("robot-empty", "stereo", [(("robot",), {})], "robot: expected 'name'"),
    ("robot-both", "stereo", [(("robot", "convention"), "dh")], "robot.convention: not allowed"),
    ("robot-convention", "sphere", [(("robot", "convention"), "xyz")], "robot.convention"),
    ("robot-joint-key", "sphere", [(("robot", "joints", 2, "a"), DELETE)], "robot.joints[2].a"),
    ("robot-mass-len", "sphere", [(("robot", "mass"), [1.0] * 5)], "robot.mass: expected 6"),
    ("robot-mass-neg", "sphere", [(("robot", "mass", 1), -1.0)], "robot.mass[1]: must be >= 0"),
    ("robot-com", "sphere", [(("robot", "com", 3), [0.0, 0.1])], "robot.com[3]: expected 3"),
    ("nan", "stereo", [((*S2, "p", 1), float("nan"))], "samples[2].p[1]: not a finite number"),
    ("inf", "stereo", [((*S1, "cov", 2, 2), float("inf"))], "samples[1].cov[2][2]: not a finite"),
    ("huge-int", "stereo", [((*S1, "t"), 10**400)], "samples[1].t: not a finite number"),
    ("not-pd", "stereo", [((*S3, "cov"), NOT_PD)], "samples[3].cov: not positive definite"),
    ("asym", "stereo", [((*S1, "cov"), ASYMMETRIC)], "samples[1].cov: not symmetric"),
    ("cov-zero", "stereo", [((*S0, "cov"), [[0.0] * 3] * 3)], "samples[0].cov: not positive def"),
    (
        "cov-shape",
        "stereo",
        [((*S0, "cov"), [[1e-8, 0], [0, 1e-8]])],
        "samples[0].cov: expected a 3x3",
    ),
    ("cov-row", "stereo", [((*S2, "cov", 1), [0.0, 1e-8])], "samples[2].cov: expected a 3x3"),
    ("cov-flat", "stereo", [((*S0, "cov"), [1e-8] * 9)], "samples[0].cov: expected a 3x3"),
    ("p-shape", "stereo", [((*S1, "p"), [0.1, 0.2])], "samples[1].p: expected 3 values, got 2"),
    ("p-type", "stereo", [((*S1, "p"), "0.1 0.2 0.3")], "samples[1].p: expected a list"),
    ("q-string", "stereo", [((*S0, "q", 0), "abc")], "samples[0].q[0]: expected a number"),
    ("q-bool", "stereo", [((*S0, "q", 3), True)], "samples[0].q[3]: expected a number"),
    ("uv-shape", "stereo", [((*S3, "uv"), [[1.0, 2.0]])], "samples[3].uv: expected a 2x2"),
    ("sigma-neg", "stereo", [((*S1, "cov"), DELETE), ((*S1, "sigma"), -0.001)], "samples[1].sigma"),
    ("sigma-zero", "dual", [((*S3, "sigma"), 0.0)], "samples[3].sigma: must be positive"),
    ("sigma-neg-sphere", "sphere", [((*S0, "sigma"), -1e-6)], "samples[0].sigma: must be positive"),
    ("cov-and-sigma", "stereo", [((*S2, "sigma"), 0.001)], "samples[2].sigma: give either"),
    ("units-length", "stereo", [(("units", "length"), "inch")], "units.length: expected 'm' or"),
    ("units-angle", "stereo", [(("units", "angle"), "grad")], "units.angle: expected 'rad' or"),
    ("units-time", "sphere", [(("units",), {"time": "h"})], "units.time: expected 's' or 'ms'"),
    ("units-key", "stereo", [(("units", "mass"), "kg")], "units.mass: unknown field"),
    ("known", "stereo", [(("known", 1), "camera")], "known[1]: no frame named 'camera'"),
    ("known-twice", "stereo", [(("known", 1), "tool")], "known[1]: 'tool' listed twice"),
    ("approach-0", "stereo", [((*S0, "approach", 2), 0)], "samples[0].approach[2]: expected +1"),
    ("approach-2", "stereo", [((*S3, "approach", 0), 2)], "samples[3].approach[0]: expected +1"),
    ("approach-len", "stereo", [((*S1, "approach"), [1, 1])], "samples[1].approach: expected 6"),
    ("stereo-q", "stereo", [((*S1, "q"), DELETE)], "samples[1].q: required field missing"),
    ("stereo-p", "stereo", [((*S2, "p"), DELETE)], "samples[2].p: required field missing"),
    ("stereo-cov", "stereo", [((*S2, "cov"), DELETE)], "samples[2].cov: required field missing"),
    ("stereo-group", "stereo", [((*S0, "group"), 1)], "samples[0].group: not a field of method"),
    ("unknown-field", "stereo", [((*S0, "colour"), 1)], "samples[0].colour: unknown field"),
    ("extra-str", "stereo", [((*S2, "extra", "gain"), "hi")], "samples[2].extra.gain: expected"),
    ("t-str", "stereo", [((*S2, "t"), "noon")], "samples[2].t: expected a number"),
    ("frames-tool", "stereo", [(("frames", "tool"), DELETE)], "frames.tool: required field"),
    ("frames-rpy", "stereo", [(("frames", "tool", "rpy"), DELETE)], "frames.tool.rpy: required"),
    ("frames-unknown", "stereo", [(("frames", "world"), [0, 0, 0])], "frames.world: unknown frame"),
    ("frames-target", "stereo", [(("frames", "target"), [0, 0])], "frames.target: expected 3"),
    ("frames-missing", "stereo", [(("frames",), DELETE)], "frames: required field missing"),
    ("samples-empty", "stereo", [(("samples",), [])], "samples: no samples"),
    ("samples-type", "stereo", [(("samples",), {"q": []})], "samples: expected a list"),
    ("sample-type", "stereo", [(("samples", 2), [1, 2])], "samples[2]: expected a JSON object"),
    ("sphere-sigma", "sphere", [((*S1, "sigma"), DELETE)], "samples[1].sigma: required field"),
    ("sphere-q", "sphere", [((*S3, "q"), DELETE)], "samples[3].q: required field missing"),
    ("sphere-frame", "sphere", [(("frames", "sphere"), DELETE)], "frames.sphere: required field"),
    ("sphere-radius", "sphere", [(("frames", "sphere", "radius"), 0)], "frames.sphere.radius"),
    ("sphere-probe", "sphere", [(("probe",), DELETE)], "probe: required field missing"),
    ("stylus", "sphere", [(("probe", "stylus_radius"), DELETE)], "probe.stylus_radius: required"),
    ("stylus-neg", "sphere", [(("probe", "stylus_radius"), -1.0)], "probe.stylus_radius: must be"),
    ("group-neg", "sphere", [((*S1, "group"), -2)], "samples[1].group: must be >= 0"),
    ("group-float", "sphere", [((*S1, "group"), 1.5)], "samples[1].group: expected an integer"),
    ("sphere-p", "sphere", [((*S1, "p"), [0, 0, 0])], "samples[1].p: not a field of method"),
    ("probe-stereo", "stereo", [(("probe",), {"stylus_radius": 0.001})], "probe: not a field"),
    ("dual-chain", "dual", [((*S1, "chain"), DELETE)], "samples[1].chain: required field missing"),
    ("dual-chain-val", "dual", [((*S1, "chain"), "middle")], "samples[1].chain: expected 'left'"),
    ("dual-q-head", "dual", [((*S2, "q_head"), DELETE)], "samples[2].q_head: required field"),
    ("dual-q-arm", "dual", [((*S0, "q_arm"), DELETE)], "samples[0].q_arm: required field"),
    ("dual-p", "dual", [((*S3, "p"), DELETE)], "samples[3].p: required field missing"),
    ("dual-sigma", "dual", [((*S3, "sigma"), DELETE)], "samples[3].cov: required field missing"),
    ("dual-q", "dual", [((*S0, "q"), [0.0] * 7)], "samples[0].q: not a field of method"),
    ("dual-head-n", "dual", [((*S2, "q_head"), [0.1] * 3)], "samples[2].q_head: expected 2 joint"),
    ("dual-arm-n", "dual", [((*S2, "q_arm"), [0.1] * 6)], "samples[2].q_arm: expected 7 joint"),
    ("dual-arm-empty", "dual", [((*S0, "q_arm"), [])], "samples[0].q_arm: expected at least one"),
    ("dual-explicit", "dual", [(("robot",), sphere()["robot"])], "robot: dual_loop needs"),
    ("dual-frame", "dual", [(("frames", "left_base"), DELETE)], "frames.left_base: required"),
]


@pytest.mark.parametrize(
    ("base", "changes", "expected"), [c[1:] for c in CASES], ids=[c[0] for c in CASES]
)
def test_bad_document_names_field_and_sample(
    base: str, changes: list[tuple[tuple[Any, ...], Any]], expected: str
) -> None:
    with pytest.raises(DatasetError) as info:
        dataset_from_dict(mutated(base, *changes), source="data.json")
    assert_one_line_error(info.value, "data.json", expected)


def test_top_level_must_be_an_object() -> None:
    with pytest.raises(DatasetError, match=r"^x\.json: expected a JSON object at the top level"):
        dataset_from_dict([1, 2, 3], source="x.json")


def _write(tmp_path: Path, text: str | bytes) -> Path:
    path = tmp_path / "data.json"
    if isinstance(text, bytes):
        path.write_bytes(text)
    else:
        path.write_text(text, encoding="utf-8")
    return path


def test_malformed_json_gives_line_and_column(tmp_path: Path) -> None:
    path = _write(tmp_path, '{\n  "format": "zerocal-dataset/1",\n  "method" "stereo_target"\n}')
    with pytest.raises(DatasetError) as info:
        load_dataset(path)
    assert str(info.value) == f"{path}: not valid JSON (line 3, column 12: Expecting ':' delimiter)"


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("", "not valid JSON (line 1, column 1"),
        ("{", "not valid JSON (line 1, column 2"),
        ('{"a": 1,}', "not valid JSON"),
        (b"\xff\xfe{}", "not UTF-8 text"),
        ("[" * 100000 + "]" * 100000, "nested too deeply"),
        ('{"format": "zerocal-dataset/1", "format": "x"}', "duplicate key 'format'"),
        ("1" * 5000, "not valid JSON"),
    ],
    ids=["empty", "truncated", "trailing-comma", "not-utf8", "deep", "duplicate", "long-int"],
)
def test_unreadable_text(tmp_path: Path, text: str | bytes, expected: str) -> None:
    path = _write(tmp_path, text)
    with pytest.raises(DatasetError) as info:
        load_dataset(path)
    assert_one_line_error(info.value, str(path), expected)


@pytest.mark.parametrize("token", ["NaN", "Infinity", "-Infinity", "1e999"])
def test_non_finite_json_tokens_are_rejected_with_their_path(tmp_path: Path, token: str) -> None:
    doc = stereo()
    doc["samples"][2]["p"][1] = 12345.678
    path = _write(tmp_path, json.dumps(doc).replace("12345.678", token))
    with pytest.raises(DatasetError) as info:
        load_dataset(path)
    assert_one_line_error(info.value, str(path), "samples[2].p[1]: not a finite number")
    if token != "1e999":
        assert f"({token} is not allowed)" in str(info.value)


def test_missing_file_and_directory(tmp_path: Path) -> None:
    with pytest.raises(DatasetError) as info:
        load_dataset(tmp_path / "nope.json")
    assert str(info.value) == f"{tmp_path / 'nope.json'}: file not found"
    with pytest.raises(DatasetError) as info:
        load_dataset(tmp_path)
    assert_one_line_error(info.value, str(tmp_path), "directory")


def test_save_refuses_an_invalid_dataset(tmp_path: Path) -> None:
    dataset = dataset_from_dict(stereo())
    cov = dataset.samples.cov.copy()  # type: ignore[union-attr]
    cov[1] = np.array(NOT_PD)
    bad = dataset.with_samples(type(dataset.samples)(**{**_fields(dataset.samples), "cov": cov}))
    with pytest.raises(DatasetError, match=r"samples\[1\]\.cov: not positive definite"):
        save_dataset(bad, tmp_path / "out.json")
    assert not (tmp_path / "out.json").exists()


def _fields(value: Any) -> dict[str, Any]:
    import dataclasses

    return {f.name: getattr(value, f.name) for f in dataclasses.fields(value)}


# ----------------------------------------------------------------------- fuzzing

_json_scalars = (
    st.none()
    | st.booleans()
    | st.integers(min_value=-(10**400), max_value=10**400)
    | st.floats(allow_nan=True, allow_infinity=True)
    | st.sampled_from([0, 1, -1, 2, 1e-300, 1e300, 0.5, "", "left", "m", "mm", "deg", "ur5e"])
    | st.text(max_size=8)
)
_json_values = st.recursive(
    _json_scalars,
    lambda inner: (
        st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=6), inner, max_size=3)
    ),
    max_leaves=8,
)


def _locations(value: Any, path: tuple[Any, ...] = ()) -> list[tuple[Any, ...]]:
    out = [path]
    if isinstance(value, dict):
        for key, item in value.items():
            out += _locations(item, (*path, key))
    elif isinstance(value, list):
        for i, item in enumerate(value):
            out += _locations(item, (*path, i))
    return out


@st.composite
def mutated_documents(draw: st.DrawFn) -> dict[str, Any]:
    doc = BASES[draw(st.sampled_from(sorted(BASES)))]()
    for _ in range(draw(st.integers(1, 3))):
        locations = _locations(doc)
        path = draw(st.sampled_from(locations))
        if not path:
            continue
        parent = doc
        for key in path[:-1]:
            parent = parent[key]
        action = draw(st.sampled_from(["replace", "delete", "insert", "tweak"]))
        key = path[-1]
        if action == "replace":
            parent[key] = draw(_json_values)
        elif action == "delete":
            del parent[key]
        elif action == "insert" and isinstance(parent, list):
            parent.insert(key, copy.deepcopy(parent[key]))
        elif action == "insert":
            parent[
                draw(st.sampled_from(["extra", "sigma", "cov", "q", "chain", "group", "zz"]))
            ] = copy.deepcopy(parent[key])
        elif isinstance(parent[key], int | float) and not isinstance(parent[key], bool):
            try:
                parent[key] = parent[key] * draw(st.sampled_from([-1, 0, 1000, 1e-3, 1e200]))
            except OverflowError:
                parent[key] = float("inf")
    return doc


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(mutated_documents())
def test_mutated_documents_load_or_raise_dataset_error(doc: dict[str, Any]) -> None:
    try:
        dataset = dataset_from_dict(doc, source="fuzz.json")
    except DatasetError as exc:
        assert_one_line_error(exc, "fuzz.json", "")
        return
    again = dataset_from_dict(dataset_to_dict(dataset))
    assert again == dataset


@settings(max_examples=100, deadline=None)
@given(doc=mutated_documents(), cut=st.integers(0, 10**6), byte=st.integers(0, 255))
def test_corrupted_files_load_or_raise_dataset_error(
    tmp_path_factory: pytest.TempPathFactory, doc: dict[str, Any], cut: int, byte: int
) -> None:
    raw = bytearray(json.dumps(doc, allow_nan=True).encode())
    raw[cut % len(raw)] = byte
    path = tmp_path_factory.mktemp("fuzz") / "data.json"
    path.write_bytes(bytes(raw))
    try:
        load_dataset(path)
    except DatasetError as exc:
        assert_one_line_error(exc, str(path), "")


def test_numpy_values_in_a_dict_are_accepted() -> None:
    doc = stereo()
    doc["samples"][0]["q"] = np.array(doc["samples"][0]["q"])
    doc["samples"][0]["t"] = np.float64(21.27)
    doc["frames"]["target"] = (0.45, 0.15, 0.02)
    assert dataset_from_dict(doc) == dataset_from_dict(stereo())


@pytest.mark.parametrize(
    ("path", "value", "expected"),
    [
        (("samples", 1, "t"), {1.0}, "samples[1].t: unsupported value of type set"),
        (("samples", 1, "extra"), {3: 1.0}, "samples[1].extra: keys must be strings"),
        (("samples", 0, "q", 2), np.nan, "samples[0].q[2]: not a finite number"),
    ],
)
def test_python_values_json_cannot_hold(path: tuple[Any, ...], value: Any, expected: str) -> None:
    with pytest.raises(DatasetError) as info:
        dataset_from_dict(mutated("stereo", (path, value)))
    assert_one_line_error(info.value, "<dict>", expected)
