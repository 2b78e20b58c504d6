"""Capabilities as typed interfaces (hostpc.robots.base) and the driver table
(hostpc.robots.drivers): what each adapter offers is its `Capabilities`, the wrappers carry
the wrapped adapter's, a missing one is one line naming the method, the call and the driver.
Real adapters only: a replay from a small tape, a recording around it, the UR adapter with
no ur_rtde interface (nothing here talks to a robot)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from hostpc.errors import InputError
from hostpc.robots.base import MissingCapability, Need, check_needs, targets_of, tracker_of
from hostpc.robots.drivers import DRIVER_NAMES, DRIVERS, driver_named
from hostpc.robots.ur import UrAdapter
from hostpc.robots.ur_precheck import UrControllerInfo
from hostpc.sensors.recording import (
    RECORDING_FORMAT,
    TAPE_FILE,
    RecordingAdapter,
    RecordingHeader,
    ReplayAdapter,
)

MEASUREMENT = {"q": [0.1, -0.2], "t": 3.5, "targets": [
    {"chain": "left", "p": [0.01, 0.02, 0.5], "cov": np.eye(3).tolist(),
     "uv": [[100.0, 200.0], [90.0, 200.0]]}]}


def _tape(folder: Path, measure_targets: bool) -> Path:
    folder.mkdir(parents=True)
    (folder / "recording.json").write_text(json.dumps({
        "format": RECORDING_FORMAT, "settings": {"method": "dual_loop"},
        "measure_targets": measure_targets}))
    entry = {"n": 0, "call": "measure_targets", "args": {}, "result": MEASUREMENT}
    (folder / TAPE_FILE).write_text(json.dumps(entry) + "\n")
    return folder


def test_a_missing_capability_names_the_method_the_call_and_the_driver(tmp_path: Path) -> None:
    replay = ReplayAdapter(_tape(tmp_path / "none", measure_targets=False))
    assert replay.capabilities.targets is None and replay.capabilities.tracker is None
    with pytest.raises(MissingCapability, match=r"--method dual_loop needs a controller that "
                       r"measures targets \(measure_targets\); the replay driver"):
        check_needs(replay, (Need.TARGETS,), "--method dual_loop")
    with pytest.raises(InputError, match=r"\(measure_tracker\); the replay driver"):
        tracker_of(replay, "--method world_point")
    check_needs(replay, (), "--method stereo_target")  # nothing needed: nothing to check


async def test_a_recording_records_the_wrapped_target_camera(tmp_path: Path) -> None:
    replay = ReplayAdapter(_tape(tmp_path / "tape", measure_targets=True))
    check_needs(replay, (Need.TARGETS,), "--method dual_loop")
    recording = RecordingAdapter(replay, tmp_path / "again", RecordingHeader(settings=None))
    assert recording.driver == "replay"
    camera = targets_of(recording, "--method dual_loop")
    measurement = await camera.measure_targets()
    await recording.close()
    assert measurement.q.tolist() == MEASUREMENT["q"] and measurement.targets[0].chain == "left"
    header = json.loads((tmp_path / "again" / "recording.json").read_text())
    assert header["measure_targets"] is True
    entry = json.loads((tmp_path / "again" / TAPE_FILE).read_text().splitlines()[0])
    assert entry["call"] == "measure_targets" and entry["result"] == MEASUREMENT


def test_the_ur_adapter_offers_its_offset_export_and_no_sensor(tmp_path: Path) -> None:
    info = UrControllerInfo((5, 11, 1, 0), "URSoftware 5.11", "UR5", "", True)
    adapter = UrAdapter("127.0.0.1", info, None, None, None)
    export = adapter.capabilities.offset_export
    assert export is not None and adapter.capabilities.targets is None
    paths = export.export_offsets(tmp_path, "ur5e", np.full(6, 1e-3))
    assert sorted(p.name for p in paths.values()) == [
        "ur_calibration.yaml", "ur_joints.urdf.xml", "ur_offsets.script"]
    with pytest.raises(MissingCapability, match=r"\(measure_tracker\); the ur driver"):
        check_needs(adapter, (Need.TRACKER,), "--method world_point")


def test_the_driver_table_is_the_one_place_a_driver_is_chosen() -> None:
    assert DRIVER_NAMES == ("zerocal", "ur")
    assert driver_named("ur").camera_service and not driver_named("zerocal").camera_service
    assert DRIVERS["zerocal"].no_rollback is None
    assert "not applicable to a UR" in (DRIVERS["ur"].no_rollback or "")
    with pytest.raises(InputError, match="--driver 'kuka': expected one of zerocal, ur"):
        driver_named("kuka")
