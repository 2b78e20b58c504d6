"""A kind's own top-level block (sphere_probe's ``probe``) is read by its file face into a
typed value (``Dataset.blocks``), written back byte for byte, range-checked on load, and
refused in another kind's file, all without the dataset layer naming it."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from hostpc.dataset import dataset_from_dict, dataset_to_dict, load_dataset, save_dataset
from hostpc.errors import DatasetError
from hostpc.kinds.sphere_probe.file_face import Probe, probe_blocks, stylus_radius
from tests.hostpc.test_dataset import sphere_doc, stereo_doc


def test_probe_block_round_trips_through_its_typed_value(tmp_path: Path) -> None:
    document = sphere_doc()
    dataset = dataset_from_dict(document)
    assert dataset.blocks == probe_blocks(0.0015)
    assert isinstance(dataset.blocks["probe"], Probe) and stylus_radius(dataset) == 0.0015
    assert "probe" not in dataset.extra_fields
    written = dataset_to_dict(dataset)
    assert written["probe"] == document["probe"]
    assert list(written).index("probe") == list(written).index("known") + 1
    first, second = tmp_path / "first.json", tmp_path / "second.json"
    save_dataset(dataset, first)
    save_dataset(load_dataset(first), second)
    assert first.read_bytes() == second.read_bytes()
    assert json.loads(first.read_text())["probe"] == {"stylus_radius": 0.0015}


def test_probe_block_is_checked_on_load() -> None:
    document = sphere_doc()
    document["probe"] = {"stylus_radius": 1000.0}
    with pytest.raises(DatasetError, match=r"probe\.stylus_radius: 1000 m is outside the "
                                           "physical range"):
        dataset_from_dict(document, "doc")
    document["probe"] = {"stylus_radius": 0.001, "tip": 1.0}
    with pytest.raises(DatasetError, match=r"probe\.tip"):
        dataset_from_dict(document, "doc")


def test_another_kinds_block_is_not_a_field_of_this_method() -> None:
    document = stereo_doc()
    document["probe"] = {"stylus_radius": 0.001}
    with pytest.raises(DatasetError, match="probe: not a field of method 'stereo_target'"):
        dataset_from_dict(document, "doc")
