"""Dataset files: round trips, unit conversion and the in-memory value (hostpc.dataset)."""

from __future__ import annotations

import copy
import dataclasses
import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from hostpc.dataset import (
    Dataset,
    FramePose,
    Samples,
    SphereFrame,
    dataset_from_dict,
    dataset_to_dict,
    load_dataset,
    save_dataset,
)
from hostpc.kinds.sphere_probe.file_face import reference_sphere, stylus_radius

RNG_SEED = 20240601


def _awkward(rng: np.random.Generator, shape: tuple[int, ...], scale: float = 1.0) -> Any:
    """Floats whose shortest decimal form is long, so an inexact writer would fail."""
    return (rng.standard_normal(shape) * scale / 3.0).tolist()


def _spd(rng: np.random.Generator, scale: float) -> list[list[float]]:
    root = rng.standard_normal((3, 3))
    cov = root @ root.T + 3 * np.eye(3)
    cov = (cov + cov.T) / 2 * scale
    return cov.tolist()


def stereo_doc() -> dict[str, Any]:
    """A valid stereo_target document in SI with every optional field somewhere."""
    rng = np.random.default_rng(RNG_SEED)
    samples: list[dict[str, Any]] = [
        {
            "q": _awkward(rng, (6,), 3.0),
            "p": _awkward(rng, (3,), 0.5),
            "cov": _spd(rng, 1e-8),
            "t": 21.27,
            "approach": [-1, 1, 1, 1, -1, 1],
            "temperature": 31.5,
            "speed": 0.25,
            "extra": {"gain": 1.0 / 3.0, "exposure": 12.5},
            "uv": [[640.25, 480.5], [610.125, 480.75]],
        },
        {"q": _awkward(rng, (6,), 3.0), "p": _awkward(rng, (3,), 0.5), "sigma": 1.5e-4},
        {"q": _awkward(rng, (6,), 3.0), "p": _awkward(rng, (3,), 0.5), "cov": _spd(rng, 1e-9)},
        {
            "q": [0, -0.0, 1e-300, 2.5, -3, 0.1 + 0.2],
            "p": [0.1, 0.2, 0.3],
            "cov": [[2.2e-9, 0, 0], [0, 2.2e-9, 0], [0, 0, 7.3e-8]],
            "extra": {"gain": 2.0},
        },
    ]
    return {
        "format": "zerocal-dataset/1",
        "method": "stereo_target",
        "units": {"length": "m", "angle": "rad", "time": "s"},
        "robot": {"name": "ur5e"},
        "frames": {
            "tool": {"xyz": [0.0, 0.045, 0.06], "rpy": [0.0, 0.0, 1.5708]},
            "target": [0.45, 0.15, 0.02],
            "camera": {"model": "pinhole-stereo", "fx": 1200.5, "baseline_m": 0.12},
        },
        "known": ["target"],
        "samples": samples,
        "acquisition": {"operator": "test", "poses": [1, 2, 3]},
    }


def sphere_doc() -> dict[str, Any]:
    """A valid sphere_probe document with an explicit MDH robot and mass data."""
    rng = np.random.default_rng(RNG_SEED + 1)
    joints = [
        {"a": a, "alpha": alpha, "d": d, "theta": theta}
        for a, alpha, d, theta in zip(
            [0.0, 0.15, 0.61, 0.02, 0.0, 0.0],
            [0.0, -np.pi / 2, 0.0, -np.pi / 2, np.pi / 2, -np.pi / 2],
            [0.45, 0.0, 0.0, 0.64, 0.0, 0.1],
            [0.0, -np.pi / 2, 0.0, 0.0, 0.0, 0.0],
            strict=True,
        )
    ]
    samples = []
    for i in range(10):
        sample: dict[str, Any] = {"q": _awkward(rng, (6,), 2.0), "sigma": 2e-6 * (1 + i)}
        if i % 2 == 0:
            sample.update(group=i // 5, t=0.5 * i, speed=0.01, approach=[1, -1, 1, -1, 1, -1])
        if i == 3:
            sample.update(temperature=24.0, extra={"force": 1.25})
        samples.append(sample)
    return {
        "format": "zerocal-dataset/1",
        "method": "sphere_probe",
        "robot": {
            "convention": "mdh",
            "joints": joints,
            "mass": [10.0, 8.5, 6.25, 3.0, 2.0, 0.5],
            "com": _awkward(rng, (6, 3), 0.1),
        },
        "frames": {
            "tool": {"xyz": [0.0, 0.0, 0.125]},
            "sphere": {"center": [0.8, 0.1, 0.3], "radius": 0.0127},
        },
        "known": ["sphere"],
        "probe": {"stylus_radius": 0.0015},
        "samples": samples,
    }


def dual_doc() -> dict[str, Any]:
    """A valid dual_loop document; the left arm has 7 joints, the right arm 6."""
    rng = np.random.default_rng(RNG_SEED + 2)
    samples = []
    for i in range(6):
        chain = "left" if i % 2 == 0 else "right"
        sample: dict[str, Any] = {
            "chain": chain,
            "q_head": _awkward(rng, (2,), 0.5),
            "q_arm": _awkward(rng, (7 if chain == "left" else 6,), 2.0),
            "p": _awkward(rng, (3,), 0.5),
        }
        if i < 3:
            sample["cov"] = _spd(rng, 1e-8)
        else:
            sample["sigma"] = 3e-4
        if i == 0:
            sample.update(t=1.0, approach=[1, 1, -1, 1, -1, 1, 1], extra={"lux": 300.0})
        if i == 1:
            sample.update(temperature=30.0, approach=[1, 1, -1, 1, -1, 1])
        samples.append(sample)
    return {
        "format": "zerocal-dataset/1",
        "method": "dual_loop",
        "units": {"length": "m", "angle": "rad"},
        "robot": {"name": "humanoid_upper"},
        "frames": {
            "camera": {"xyz": [0.05, 0.0, 0.1], "rpy": [-1.5708, 0.0, -1.5708]},
            "left_base": {"xyz": [0.0, 0.2, -0.3], "rpy": [0.0, 0.0, 0.0]},
            "right_base": {"xyz": [0.0, -0.2, -0.3], "rpy": [0.0, 0.0, 0.0]},
            "left_target": [0.0, 0.0, 0.05],
            "right_target": [0.0, 0.0, 0.05],
        },
        "known": [],
        "samples": samples,
    }


DOCS = {"stereo_target": stereo_doc, "sphere_probe": sphere_doc, "dual_loop": dual_doc}


# ----------------------------------------------------------------------- round trips


@pytest.mark.parametrize("method", list(DOCS))
def test_round_trip_through_a_file_is_exact(method: str, tmp_path: Path) -> None:
    original = dataset_from_dict(DOCS[method]())
    path = tmp_path / "data.json"
    save_dataset(original, path)
    loaded = load_dataset(path)
    assert loaded == original
    # and again: the second file is byte-identical to the first
    save_dataset(loaded, tmp_path / "again.json")
    assert (tmp_path / "again.json").read_text() == path.read_text()


@pytest.mark.parametrize("method", list(DOCS))
def test_loaded_values_are_the_numbers_of_the_file(method: str) -> None:
    doc = DOCS[method]()
    dataset = dataset_from_dict(doc)
    q_key = "q_arm" if method == "dual_loop" else "q"
    for i, sample in enumerate(doc["samples"]):
        n = len(sample[q_key])
        assert dataset.samples.q[i, :n].tolist() == [float(v) for v in sample[q_key]]
        assert np.all(np.isnan(dataset.samples.q[i, n:]))
        if "p" in sample:
            assert dataset.samples.p is not None
            assert dataset.samples.p[i].tolist() == sample["p"]
        if "cov" in sample:
            assert dataset.samples.cov is not None
            assert dataset.samples.cov[i].tolist() == sample["cov"]
        elif "sigma" in sample and method != "sphere_probe":
            assert dataset.samples.cov is not None
            assert dataset.samples.cov[i].tolist() == (sample["sigma"] ** 2 * np.eye(3)).tolist()
        assert np.isnan(dataset.samples.t[i]) == ("t" not in sample)
        assert np.all(np.isnan(dataset.samples.approach[i])) == ("approach" not in sample)
        if "approach" in sample:
            assert dataset.samples.approach[i, :n].tolist() == sample["approach"]


def test_round_trip_keeps_optional_context_and_unknown_fields() -> None:
    doc = stereo_doc()
    dataset = dataset_from_dict(doc)
    samples = dataset.samples
    assert samples.t.tolist()[0] == 21.27 and np.isnan(samples.t[1:]).all()
    assert samples.temperature[0] == 31.5 and samples.speed[0] == 0.25
    assert samples.extra["gain"].tolist()[::3] == [1.0 / 3.0, 2.0]
    assert np.isnan(samples.extra["exposure"][1:]).all()
    assert samples.uv is not None and samples.uv[0].tolist() == doc["samples"][0]["uv"]
    assert np.isnan(samples.uv[1:]).all()
    assert samples.group.tolist() == [-1, -1, -1, -1]
    assert samples.sigma is None and samples.chain is None and samples.q_head is None
    assert dataset.frames["camera"] == doc["frames"]["camera"]
    assert dataset.extra_fields == {"acquisition": doc["acquisition"]}
    written = dataset_to_dict(dataset)
    assert written["acquisition"] == doc["acquisition"]
    assert written["samples"][0]["extra"] == doc["samples"][0]["extra"]
    assert "t" not in written["samples"][1] and "approach" not in written["samples"][2]


def test_sphere_probe_fields() -> None:
    dataset = dataset_from_dict(sphere_doc())
    assert dataset.samples.p is None and dataset.samples.cov is None
    assert dataset.samples.sigma is not None and dataset.samples.sigma[1] == 4e-6
    assert dataset.samples.group.tolist() == [0, -1, 0, -1, 0, -1, 1, -1, 1, -1]
    assert dataset.frames["sphere"] == SphereFrame(center=np.array([0.8, 0.1, 0.3]), radius=0.0127)
    assert dataset.frames["tool"] == FramePose(xyz=np.array([0, 0, 0.125]), rpy=np.zeros(3))
    assert stylus_radius(dataset) == 0.0015
    assert reference_sphere(dataset).radius == 0.0127
    assert dataset.robot.convention == "mdh" and dataset.robot.n_joints == 6
    assert dataset.robot.mass is not None and dataset.robot.mass[2] == 6.25
    assert dataset.n_joints == 6 and dataset.n_samples == 10


def test_dual_loop_fields() -> None:
    dataset = dataset_from_dict(dual_doc())
    samples = dataset.samples
    assert samples.chain is not None and samples.chain.tolist()[:2] == ["left", "right"]
    assert samples.q_head is not None and samples.q_head.shape == (6, 2)
    assert samples.q.shape == (6, 7)  # padded to the widest arm
    assert np.isnan(samples.q[1, 6]) and not np.isnan(samples.q[0, 6])
    assert samples.cov is not None and samples.cov[4].tolist() == (3e-4**2 * np.eye(3)).tolist()
    assert dataset.robot.name == "humanoid_upper"
    assert isinstance(dataset.frames["left_base"], FramePose)
    assert dataset.frames["left_target"].tolist() == [0.0, 0.0, 0.05]
    assert dataset.point("right_target").tolist() == [0.0, 0.0, 0.05]
    assert dataset.pose("camera").rpy.tolist() == [-1.5708, 0.0, -1.5708]
    with pytest.raises(TypeError):
        dataset.pose("left_target")


def test_equality_sees_a_one_ulp_change() -> None:
    dataset = dataset_from_dict(stereo_doc())
    q = dataset.samples.q.copy()
    q[2, 3] = np.nextafter(q[2, 3], np.inf)
    changed = dataset.with_samples(dataclasses.replace(dataset.samples, q=q))
    assert changed != dataset
    assert dataset.with_samples(dataset.samples) == dataset


def test_values_are_frozen() -> None:
    dataset = dataset_from_dict(stereo_doc())
    with pytest.raises(ValueError):
        dataset.samples.q[0, 0] = 1.0
    with pytest.raises(dataclasses.FrozenInstanceError):
        dataset.method = "sphere_probe"  # type: ignore[misc]
    with pytest.raises(TypeError):
        dataset.frames["target"] = np.zeros(3)  # type: ignore[index]


def test_subset_picks_rows_of_every_array() -> None:
    dataset = dataset_from_dict(dual_doc())
    part = dataset.samples.subset([4, 0])
    assert part.n == 2 and len(part) == 2
    assert part.q[1].tolist() == dataset.samples.q[0].tolist()
    assert part.chain is not None and part.chain.tolist() == ["left", "left"]
    assert part.q_head is not None and part.q_head[0].tolist() == dataset.samples.q_head[4].tolist()
    assert part.extra["lux"][1] == 300.0 and np.isnan(part.extra["lux"][0])
    mask = np.arange(6) % 2 == 1
    assert dataset.samples.subset(mask).chain.tolist() == ["right"] * 3  # type: ignore[union-attr]
    fold = dataset.with_samples(part)
    assert fold.n_samples == 2 and fold.frames is not None


def test_samples_constructed_in_code_fill_absent_context() -> None:
    samples = Samples(q=np.zeros((3, 6)), p=np.zeros((3, 3)), cov=np.tile(np.eye(3), (3, 1, 1)))
    assert np.isnan(samples.t).all() and samples.t.shape == (3,)
    assert samples.approach.shape == (3, 6) and samples.group.tolist() == [-1, -1, -1]
    with pytest.raises(ValueError, match="Samples.p"):
        Samples(q=np.zeros((3, 6)), p=np.zeros((2, 3)))


# ----------------------------------------------------------------------- units

LENGTH = {"m": 1.0, "mm": 1000.0}
TIME = {"s": 1.0, "ms": 1000.0}


def _in_units(doc: dict[str, Any], length: str, angle: str, time: str) -> dict[str, Any]:
    """Re-express an SI document in other units (independently of the code under test)."""
    out = copy.deepcopy(doc)
    scale = LENGTH[length]
    tscale = TIME[time]

    def ln(v: Any) -> Any:
        return (np.asarray(v, dtype=float) * scale).tolist()

    def ang(v: Any) -> Any:
        return np.rad2deg(v).tolist() if angle == "deg" else v

    out["units"] = {"length": length, "angle": angle, "time": time}
    for name, frame in out["frames"].items():
        if name == "camera" and out["method"] == "stereo_target":
            continue  # the camera model is passed through unconverted
        if isinstance(frame, list):
            out["frames"][name] = ln(frame)
        elif "center" in frame:
            frame.update(center=ln(frame["center"]), radius=ln(frame["radius"]))
        else:
            frame["xyz"] = ln(frame["xyz"])
            if "rpy" in frame:
                frame["rpy"] = ang(frame["rpy"])
    robot = out["robot"]
    for row in robot.get("joints", []):
        row.update(a=ln(row["a"]), d=ln(row["d"]), alpha=ang(row["alpha"]))
        row["theta"] = ang(row["theta"])
    if "com" in robot:
        robot["com"] = ln(robot["com"])
    if "probe" in out:
        out["probe"]["stylus_radius"] = ln(out["probe"]["stylus_radius"])
    for sample in out["samples"]:
        for key in ("q", "q_arm", "q_head"):
            if key in sample:
                sample[key] = ang(sample[key])
        for key in ("p", "sigma"):
            if key in sample:
                sample[key] = ln(sample[key])
        if "cov" in sample:
            sample["cov"] = (np.asarray(sample["cov"]) * scale**2).tolist()
        if "t" in sample:
            sample["t"] = sample["t"] * tscale
        if "speed" in sample:
            sample["speed"] = sample["speed"] * scale / tscale
    return out


def _assert_close(a: Any, b: Any, where: str = "") -> None:
    """Recursive comparison with a relative tolerance for floats."""
    if dataclasses.is_dataclass(a):
        assert type(a) is type(b), where
        for f in dataclasses.fields(a):
            _assert_close(getattr(a, f.name), getattr(b, f.name), f"{where}.{f.name}")
    elif isinstance(a, np.ndarray) and a.dtype.kind == "f":
        np.testing.assert_allclose(a, b, rtol=1e-12, atol=0, err_msg=where)
    elif isinstance(a, dict) or hasattr(a, "keys"):
        assert set(a.keys()) == set(b.keys()), where
        for key in a:
            _assert_close(a[key], b[key], f"{where}[{key}]")
    elif isinstance(a, np.ndarray):
        assert np.array_equal(a, b), where
    else:
        assert a == b, where


@pytest.mark.parametrize("method", list(DOCS))
@pytest.mark.parametrize(
    ("length", "angle", "time"),
    [("mm", "deg", "s"), ("mm", "rad", "ms"), ("m", "deg", "ms"), ("mm", "deg", "ms")],
)
def test_other_units_load_as_the_si_file(method: str, length: str, angle: str, time: str) -> None:
    si_doc = DOCS[method]()
    converted = dataset_from_dict(_in_units(si_doc, length, angle, time))
    _assert_close(converted, dataset_from_dict(si_doc))


def test_unit_conversion_spot_values() -> None:
    doc = stereo_doc()
    doc["units"] = {"length": "mm", "angle": "deg", "time": "ms"}
    doc["frames"]["tool"] = {"xyz": [0.0, 45.0, 60.0], "rpy": [0.0, 0.0, 90.0]}
    doc["samples"][0].update(q=[90, -45, 0, 180, 0, 360], t=1500.0, speed=250.0)
    doc["samples"][1]["sigma"] = 2.0
    doc["samples"][0]["cov"] = [[4.0, 0, 0], [0, 9.0, 0], [0, 0, 16.0]]
    dataset = dataset_from_dict(doc)
    np.testing.assert_allclose(dataset.frames["tool"].xyz, [0.0, 0.045, 0.06], rtol=1e-15)
    np.testing.assert_allclose(dataset.frames["tool"].rpy, [0, 0, np.pi / 2], rtol=1e-15)
    np.testing.assert_allclose(
        dataset.samples.q[0], np.array([0.5, -0.25, 0, 1, 0, 2]) * np.pi, rtol=1e-15
    )
    assert dataset.samples.t[0] == pytest.approx(1.5, rel=1e-15)
    assert dataset.samples.speed[0] == pytest.approx(250.0, rel=1e-15)  # mm/ms == m/s
    assert dataset.samples.cov is not None
    np.testing.assert_allclose(np.diag(dataset.samples.cov[0]), [4e-6, 9e-6, 16e-6], rtol=1e-15)
    np.testing.assert_allclose(np.diag(dataset.samples.cov[1]), [4e-6] * 3, rtol=1e-15)
    saved = dataset_to_dict(dataset)
    assert saved["units"] == {"length": "m", "angle": "rad", "time": "s"}
    assert saved["frames"]["tool"]["xyz"] == dataset.frames["tool"].xyz.tolist()


def test_saved_file_is_plain_json_with_si_units(tmp_path: Path) -> None:
    path = tmp_path / "out.json"
    save_dataset(dataset_from_dict(sphere_doc()), path)
    text = path.read_text(encoding="utf-8")
    doc = json.loads(text)
    assert doc["format"] == "zerocal-dataset/1" and doc["method"] == "sphere_probe"
    assert doc["units"] == {"length": "m", "angle": "rad", "time": "s"}
    assert "NaN" not in text and "\n  " in text
    assert not list(tmp_path.glob(".zerocal-*"))  # no temporary file left behind


def test_dataset_constructed_in_code_saves_and_loads(tmp_path: Path) -> None:
    from hostpc.dataset import RobotDescription

    n = 4
    dataset = Dataset(
        method="stereo_target",
        robot=RobotDescription(name="ur10e"),
        frames={
            "tool": FramePose(xyz=np.array([0, 0, 0.1]), rpy=np.zeros(3)),
            "target": np.array([0.5, 0.0, 0.2]),
        },
        samples=Samples(
            q=np.linspace(-1, 1, n * 6).reshape(n, 6),
            p=np.full((n, 3), 0.3),
            cov=np.tile(np.eye(3) * 1e-8, (n, 1, 1)),
            t=np.array([0.0, np.nan, 2.0, 3.0]),
        ),
        known=("tool",),
    )
    save_dataset(dataset, tmp_path / "d.json")
    assert load_dataset(tmp_path / "d.json") == dataset
