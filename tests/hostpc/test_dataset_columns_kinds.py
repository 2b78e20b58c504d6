"""Column reader and column writer of every built-in kind (issue 17): the same Dataset and
the same bytes as the sample-by-sample paths; a bad sample among regular ones is still named
in one line (the column reader leaves every error to the sample-by-sample reader)."""

from __future__ import annotations

import copy
import json
import re
from typing import Any

import numpy as np
import pytest

from hostpc.dataset import reading, writing
from hostpc.dataset.reading import dataset_from_dict
from hostpc.dataset.writing import _dumps, dataset_to_dict
from hostpc.errors import DatasetError
from hostpc.model.measurements.registry import measurement_model

KINDS = ("stereo_target", "sphere_probe", "dual_loop", "world_point", "world_pose")
COLUMNAR = KINDS


def _document(method: str) -> dict[str, Any]:
    dataset = measurement_model(method).example(np.random.default_rng(5))
    return json.loads(json.dumps(dataset_to_dict(dataset)))


def _read_both(doc: dict[str, Any], monkeypatch: pytest.MonkeyPatch) -> tuple[Any, Any]:
    fast = reading._columnar_dataset(copy.deepcopy(doc), reading.measurement_kinds(()), None)
    with monkeypatch.context() as patch:
        patch.setattr(reading, "_columnar_dataset", lambda *args: None)
        slow = dataset_from_dict(copy.deepcopy(doc))
    return fast, slow


@pytest.mark.parametrize("method", COLUMNAR)
def test_read_by_columns_as_sample_by_sample(method: str,
                                             monkeypatch: pytest.MonkeyPatch) -> None:
    fast, slow = _read_both(_document(method), monkeypatch)
    assert fast is not None, "the column reader declined a regular file"
    assert fast == slow


def test_world_point_mask_given_by_some_samples_only(monkeypatch: pytest.MonkeyPatch) -> None:
    doc = _document("world_point")
    masked = [i for i, s in enumerate(doc["samples"]) if "mask" in s]
    assert 0 < len(masked) < len(doc["samples"])  # the example's file is irregular there
    fast, slow = _read_both(doc, monkeypatch)
    assert fast is not None and fast == slow
    assert fast.samples.fields["mask"][masked[0]].tolist() == doc["samples"][masked[0]]["mask"]


@pytest.mark.parametrize("given", ["cov", "sigma"])
def test_world_pose_in_file_units(given: str, monkeypatch: pytest.MonkeyPatch) -> None:
    doc = _document("world_pose")
    doc["units"] = {"length": "mm", "angle": "deg", "time": "s"}
    for i, sample in enumerate(doc["samples"]):
        if given == "sigma":
            del sample["cov"]
            sample["sigma"] = 0.02 * (1 + i % 3)
            sample["sigma_angle"] = 0.01 * (1 + i % 2)
        else:
            sample["cov"] = (np.diag([4e-4] * 3 + [1e-4] * 3) * (1 + i)).tolist()
    fast, slow = _read_both(doc, monkeypatch)
    assert fast is not None and fast == slow
    assert np.allclose(fast.samples.fields["pose_cov"][0][0, 0], 4e-10)


@pytest.mark.parametrize("method", KINDS)
def test_column_writer_writes_the_bytes_of_the_sample_writer(
        method: str, monkeypatch: pytest.MonkeyPatch) -> None:
    dataset = measurement_model(method).example(np.random.default_rng(6))
    fast = _dumps(dataset_to_dict(dataset))
    with monkeypatch.context() as patch:
        patch.setattr(writing, "_writes_columns", lambda cls: False)
        slow = _dumps(dataset_to_dict(dataset))
    assert fast == slow
    assert dataset_from_dict(json.loads(fast)) == dataset_from_dict(json.loads(slow))


def test_a_plugin_overriding_write_sample_alone_is_written_sample_by_sample() -> None:
    from hostpc.kinds.stereo_target.file_face import StereoTargetFile

    class Tagged(StereoTargetFile):
        def write_sample(self, samples: Any, index: int) -> tuple[dict[str, Any], int]:
            out, n = super().write_sample(samples, index)
            return {**out, "tag": index}, n

    assert writing._writes_columns(StereoTargetFile)
    assert not writing._writes_columns(Tagged)
    samples = measurement_model("stereo_target").example(np.random.default_rng(7)).samples
    assert writing._samples_to_json(Tagged(), samples)[3]["tag"] == 3


@pytest.mark.parametrize(("method", "index", "field", "value", "message"), [
    ("world_point", 9, "mask", [1, 2, 1], "samples[9].mask[1]: expected 0 or 1"),
    ("world_point", 4, "mask", [0, 0, 0], "samples[4].mask: no axis measured"),
    ("world_point", 7, "marker", "zz", "samples[7].marker: no marker 'zz'"),
    ("world_point", 3, "cov", [[1e-8, 0, 0], [0, -1e-8, 0], [0, 0, 1e-8]],
     "samples[3].cov: not positive definite"),
    ("world_pose", 6, "cov", (np.eye(6) + np.eye(6, k=1) * 0.5).tolist(),
     "samples[6].cov: not symmetric"),
    ("world_pose", 2, "rpy", [0.1, 0.2], "samples[2].rpy"),
    ("world_pose", 11, "p", [0.1, "0.2", 0.3], "samples[11].p[1]"),
    ("dual_loop", 5, "chain", "middle", "samples[5].chain"),
    ("dual_loop", 8, "q_arm", [0.1, 0.2], "samples[8].q_arm: expected"),
    ("dual_loop", 3, "q_head", [0.1, 0.2, 0.3], "samples[3].q_head: expected"),
    ("dual_loop", 10, "sigma", 1e-4, "samples[10].sigma: give either 'cov' or 'sigma'"),
    ("sphere_probe", 4, "group", -1, "samples[4].group: must be >= 0"),
    ("sphere_probe", 6, "group", 1.5, "samples[6].group"),
    ("sphere_probe", 2, "sigma", 0.0, "samples[2].sigma: must be positive"),
])
def test_a_bad_sample_among_regular_ones_is_named_in_one_line(
        method: str, index: int, field: str, value: Any, message: str) -> None:
    doc = _document(method)
    doc["samples"][index][field] = value
    with pytest.raises(DatasetError, match=re.escape(message)) as error:
        dataset_from_dict(doc, "data.json")
    assert "\n" not in str(error.value)


def test_sphere_probe_group_given_by_some_samples_only(
        monkeypatch: pytest.MonkeyPatch) -> None:
    doc = _document("sphere_probe")
    for sample in doc["samples"][::3]:
        sample.pop("group", None)
    fast, slow = _read_both(doc, monkeypatch)
    assert fast is not None and fast == slow
    assert fast.samples.group[0] == -1 and np.any(fast.samples.group >= 0)
