"""The column reader (hostpc.dataset.reading_columns) gives the same Dataset as the
sample-by-sample reader, and leaves every error to the latter (which names the sample)."""

from __future__ import annotations

import copy
import json
import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from hostpc.dataset import reading
from hostpc.dataset.reading import dataset_from_dict
from hostpc.errors import DatasetError

EXAMPLES = sorted((Path(__file__).parents[2] / "examples").glob("ur5e_stereo*[!h].json"))


def _slow(doc: dict[str, Any], monkeypatch: pytest.MonkeyPatch) -> Any:
    with monkeypatch.context() as patch:
        patch.setattr(reading, "_columnar_dataset", lambda *args: None)
        return dataset_from_dict(copy.deepcopy(doc))


def _fast(doc: dict[str, Any]) -> Any:
    used = reading._columnar_dataset(copy.deepcopy(doc), reading.measurement_kinds(()), None)
    assert used is not None, "the column reader declined a regular file"
    return dataset_from_dict(copy.deepcopy(doc))


def _regular_stereo(length: str = "m", angle: str = "rad", time: str = "s",
                    sigma: bool = False) -> dict[str, Any]:
    rng = np.random.default_rng(17)
    scale = 1000.0 if length == "mm" else 1.0
    samples = []
    for i in range(40):
        root = rng.standard_normal((3, 3))
        cov = (root @ root.T + 3 * np.eye(3)) * 1e-8 * scale**2
        q = rng.standard_normal(6) / 3
        sample: dict[str, Any] = {
            "q": (np.rad2deg(q) if angle == "deg" else q).tolist(),
            "p": (rng.standard_normal(3) / 7 * scale).tolist(),
            "t": 0.5 * i * (1000.0 if time == "ms" else 1.0), "temperature": 21.0 + i / 3,
            "speed": 0.1 + i / 7, "approach": rng.choice([-1, 1], 6).tolist(),
            "uv": (rng.standard_normal((2, 2)) * 300).tolist()}
        if sigma:
            sample["sigma"] = 1e-4 * (1 + i) / 3 * scale
        else:
            sample["cov"] = ((cov + cov.T) / 2).tolist()
        samples.append(sample)
    return {"format": "zerocal-dataset/1", "method": "stereo_target",
            "units": {"length": length, "angle": angle, "time": time},
            "robot": {"name": "ur5e"},
            "frames": {"tool": {"xyz": [0.0, 0.045, 0.06], "rpy": [0.0, 0.0, 1.5708]},
                       "target": [0.45, 0.15, 0.02]},
            "samples": samples, "acquisition": {"operator": "test"}}


@pytest.mark.parametrize("path", EXAMPLES, ids=lambda p: p.name)
def test_examples_read_by_columns_as_sample_by_sample(path: Path,
                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    doc = json.loads(path.read_text())
    assert _fast(doc) == _slow(doc, monkeypatch)


@pytest.mark.parametrize(("length", "angle", "time", "sigma"),
                         [("m", "rad", "s", False), ("mm", "deg", "ms", False),
                          ("m", "rad", "s", True), ("mm", "deg", "s", True)])
def test_units_and_sigma_read_by_columns_as_sample_by_sample(
        length: str, angle: str, time: str, sigma: bool, monkeypatch: pytest.MonkeyPatch
) -> None:
    doc = _regular_stereo(length, angle, time, sigma)
    assert _fast(doc) == _slow(doc, monkeypatch)


def test_sphere_probe_reads_by_columns_as_sample_by_sample(
        monkeypatch: pytest.MonkeyPatch) -> None:
    rng = np.random.default_rng(3)
    doc = {"format": "zerocal-dataset/1", "method": "sphere_probe", "robot": {"name": "ur5e"},
           "frames": {"tool": {"xyz": [0.0, 0.0, 0.125]},
                      "sphere": {"center": [0.5, 0.1, 0.3], "radius": 0.0127}},
           "probe": {"stylus_radius": 0.0015},
           "samples": [{"q": (rng.standard_normal(6) / 3).tolist(), "sigma": 2e-6 * (1 + i)}
                       for i in range(12)]}
    assert _fast(doc) == _slow(doc, monkeypatch)


@pytest.mark.parametrize(("index", "field", "value", "message"), [
    (37, "cov", [[1e-8, 0, 0], [0, -1e-8, 0], [0, 0, 1e-8]],
     "samples[37].cov: not positive definite"),
    (12, "cov", [[1e-8, 1e-9, 0], [0, 1e-8, 0], [0, 0, 1e-8]], "samples[12].cov: not symmetric"),
    (25, "q", [0.1, 0.2, 0.3], "samples[25].q: expected 6 joint angles"),
    (31, "approach", [1, 1, 1, 1, 1, 0], "samples[31].approach[5]: expected +1 or -1"),
    (5, "p", [0.1, True, 0.3], "samples[5].p[1]"),
    (8, "t", "12", "samples[8].t"),
    (39, "bogus", 1.0, "samples[39].bogus: unknown field"),
])
def test_a_bad_sample_among_regular_ones_is_named(index: int, field: str, value: Any,
                                                  message: str) -> None:
    doc = _regular_stereo()
    doc["samples"][index][field] = value
    with pytest.raises(DatasetError, match=re.escape(message)):
        dataset_from_dict(doc, "data.json")


def test_a_non_finite_number_in_a_regular_file_is_named(tmp_path: Path) -> None:
    text = json.dumps(_regular_stereo()).replace('"speed": 0.1,', '"speed": NaN,', 1)
    path = tmp_path / "data.json"
    path.write_text(text)
    with pytest.raises(DatasetError, match=r"samples\[0\]\.speed: not a finite number"):
        reading.load_dataset(path)
