"""A station's rig cache (`--rig-cache DIR`, hostpc/kinds/stereo_target/rig_cache.py): one
stereo camera mounted on robot after robot keeps its rig, named by the camera identity the
controller reports; a run reuses it only when it still fits a fresh chessboard view.

Real stub (subprocess, real sockets), real captures. A cached rig with the camera's true
model fits and costs one capture; the same rig with its left focal length 0.3 % off (a
changed focus) does not, and the run calibrates anew and replaces it."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from controller_stub.scenario.spec import Scenario
from controller_stub.sensors.stereo_target import camera_serial
from hostpc.kinds.stereo_target.rig_cache import CHECK_VIEWS, MAX_FIT_PX, cache_path
from hostpc.robots.simulator import default_sim_scenario
from hostpc.vision import load_rig, save_rig
from tests.integration.test_calibrate_sim import run_cli, truth_rig_file


def stereo_cache(tmp_path: Path) -> tuple[dict[str, Any], str, Path, Path]:
    """(the default stereo_target world, its camera's serial, an empty cache folder, the
    serial's cached rig file there)."""
    scenario = default_sim_scenario(method="stereo_target")
    serial = camera_serial(Scenario.model_validate(scenario))
    cache = tmp_path / "cache"
    cache.mkdir()
    return scenario, serial, cache, cache_path(cache, serial)


@pytest.mark.slow
def test_a_cached_rig_is_reused_when_it_fits_and_replaced_when_it_does_not(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    scenario, serial, cache, cached = stereo_cache(tmp_path)
    truth_rig_file(scenario, cached)

    out = tmp_path / "reused"
    code, _, stderr = run_cli(capsys, "calibrate", "--robot", "sim", "--out", str(out),
                              "--rig-cache", str(cache), "--no-report", "--no-push")
    assert code == 0, stderr
    assert f"rig: cached for camera {serial}" in stderr and "rig calibrated" not in stderr
    result = json.loads((out / "result.json").read_text())
    assert result["robot_time_s"]["rig"] == pytest.approx(0.1 * CHECK_VIEWS)  # the captures
    check = json.loads((out / "rig_calibration.json").read_text())
    assert check["fits"] and check["check_views"][0] == 0
    assert f"rig: cached {cached}\n" in (out / "summary.txt").read_text()
    assert max(max(pair) for pair in check["check_rms_px"]) < 0.07
    camera = json.loads((out / "run.json").read_text())["initial"]["camera"]
    assert camera["camera_serial"] == serial

    rig = load_rig(cached)
    K_left = rig.K_left.copy()
    K_left[0, 0] *= 1.003  # a changed focus: 4 px of focal length
    save_rig(dataclasses.replace(rig, K_left=K_left, rms=5.0), cached)  # and an edited RMS
    out = tmp_path / "recalibrated"
    code, _, stderr = run_cli(capsys, "calibrate", "--robot", "sim", "--out", str(out),
                              "--rig-cache", str(cache), "--no-report", "--no-push")
    assert code == 0, stderr
    assert "does not fit chessboard views 0 and" in stderr and "rig calibrated" in stderr
    report = json.loads((out / "rig_calibration.json").read_text())
    assert report["ok"] and report["cache_check"]["fits"] is False
    assert report["cache_check"]["bound_px"] == MAX_FIT_PX  # not 2.5 x 5.0 px
    assert max(max(pair) for pair in report["cache_check"]["check_rms_px"]) > MAX_FIT_PX
    assert json.loads((out / "result.json").read_text())["robot_time_s"]["rig"] > 1.5
    assert "rig: calibrated in this run\n" in (out / "summary.txt").read_text()
    stored = load_rig(cached)  # replaced by this run's calibration
    assert stored.rms > 0.0 and abs(stored.K_left[0, 0] - 1400.0) < 1.0
    assert np.allclose(stored.K_left, load_rig(out / "rig.json").K_left)


def test_cache_names_keep_serials_apart_and_short() -> None:
    assert cache_path("c", "sim-0123abcd").name == "sim-0123abcd.json"
    assert cache_path("c", "a/b") != cache_path("c", "a_b")
    assert "/" not in cache_path("c", "a/b").name and "\n" not in cache_path("c", "x\ny").name
    long_name = cache_path("c", "s" * 300).name
    assert len(long_name) <= 70 and cache_path("c", "s" * 299).name != long_name
    assert not cache_path("c", "..").name.startswith(".")


def test_an_unwritable_cache_folder_is_refused_before_anything_moves(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    afile = tmp_path / "afile"
    afile.write_text("not a folder\n")
    out = tmp_path / "run"
    code, _, stderr = run_cli(capsys, "calibrate", "--robot", "sim", "--out", str(out),
                              "--rig-cache", str(afile / "sub"), "--no-report", "--no-push")
    assert code == 2, stderr
    assert "--rig-cache" in stderr and "Traceback" not in stderr
    assert not (out / "samples.jsonl").exists() and not (out / "rig.json").exists()


@pytest.mark.slow
def test_a_broken_cached_rig_is_a_miss_and_an_unwritable_entry_a_warning(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    scenario, serial, cache, cached = stereo_cache(tmp_path)
    cached.write_text('{"image_size": [1280, 9')  # a write cut short
    out = tmp_path / "truncated"
    code, _, stderr = run_cli(capsys, "calibrate", "--robot", "sim", "--out", str(out),
                              "--rig-cache", str(cache), "--no-report", "--no-push")
    assert code == 0, stderr
    assert "the cached rig is unusable" in stderr and "rig calibrated" in stderr
    assert np.allclose(load_rig(cached).K_left, load_rig(out / "rig.json").K_left)

    cached.unlink()
    cached.mkdir()  # the entry cannot be written (a folder in its place)
    out = tmp_path / "unwritable"
    code, _, stderr = run_cli(capsys, "calibrate", "--robot", "sim", "--out", str(out),
                              "--rig-cache", str(cache), "--no-report", "--no-push")
    assert code == 0, stderr
    assert "warning: rig not stored in the cache" in stderr and "Traceback" not in stderr
    assert load_rig(out / "rig.json").rms > 0.0


@pytest.mark.slow
def test_a_focal_length_error_both_cameras_share_is_caught_by_the_tilted_view(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Both focal lengths x 1.01 (a fronto-parallel view sees only a farther board): the
    tilted check view shows it (the rig's RMS a calibration's 0.03 px: bound 0.075 px).
    World seed 3: view 0 is tilted 6 deg (its RMS 0.055 px), view 1 30 deg (0.107 px)."""
    scenario = default_sim_scenario(method="stereo_target")
    scenario["seed"] = 3
    world = tmp_path / "world.json"
    world.write_text(json.dumps(scenario))
    _, _, cache, cached = stereo_cache(tmp_path)
    rig = load_rig(truth_rig_file(scenario, cached))
    scale = np.diag([1.01, 1.01, 1.0])
    save_rig(dataclasses.replace(rig, K_left=scale @ rig.K_left, K_right=scale @ rig.K_right,
                                 rms=0.03), cached)
    out = tmp_path / "run"
    code, _, stderr = run_cli(capsys, "calibrate", "--robot", "sim", "--scenario", str(world),
                              "--out", str(out), "--rig-cache", str(cache), "--no-report",
                              "--no-push")
    assert code == 0, stderr
    assert "does not fit chessboard" in stderr, stderr
    assert load_rig(cached).K_left[0, 0] == pytest.approx(1400.0, abs=1.0)


@pytest.mark.slow
def test_a_refused_push_with_a_cached_rig_names_the_cached_file_before_force(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    scenario, _, cache, cached = stereo_cache(tmp_path)
    truth_rig_file(scenario, cached)
    out = tmp_path / "run"
    code, stdout, stderr = run_cli(capsys, "calibrate", "--robot", "sim", "--out", str(out),
                                   "--rig-cache", str(cache), "--no-report",
                                   "--max-correction", "0.000001")
    assert code != 0, stderr
    summary = (out / "summary.txt").read_text()
    hint = f"the rig was the cached {cached}: rerun without --rig-cache, or delete {cached}"
    assert hint in summary, summary
    assert summary.index(hint) < summary.index("--force")
