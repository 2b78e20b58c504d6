"""A station's rig cache (`--rig-cache DIR`, hostpc/kinds/stereo_target/rig_cache.py): one
stereo camera mounted on robot after robot keeps its rig, named by the camera identity the
controller reports; a run reuses it only when it still fits fresh chessboard views.

Real stub (subprocess, real sockets), real captures. A cached rig with the camera's true
model fits: 2 captures when the cache file names its check view (a rig calibrated for the
cache stores one), 4 for an older file without; the same rig with its left focal length 0.3 %
off (a changed focus), or both focal lengths 1 % off, does not, and the run calibrates anew
and replaces it."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from controller_stub.scenario.spec import Scenario
from controller_stub.sensors.stereo_target import StereoCamera, camera_serial
from hostpc.errors import InputError
from hostpc.kinds.stereo_target.rig_cache import (
    CHECK_VIEW_KEY,
    CHECK_VIEWS,
    MAX_FIT_PX,
    cache_path,
    fit_bound,
    focal_scaled,
    focal_signal,
    load_cached,
    view_fit,
)
from hostpc.robots.simulator import default_sim_scenario
from hostpc.vision import ChessboardSpec, load_rig, save_rig
from hostpc.vision.rig_calibration import find_chessboard
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
    # a cache file without a check view (written before they were recorded): 4 captures
    assert "4-capture check (the cache file names no check view" in stderr
    result = json.loads((out / "result.json").read_text())
    assert result["robot_time_s"]["rig"] == pytest.approx(0.1 * CHECK_VIEWS)  # the captures
    check = json.loads((out / "rig_calibration.json").read_text())
    assert check["fits"] and check["check_views"][0] == 0 and check["captures"] == CHECK_VIEWS
    assert f"rig: cached {cached} (4-capture check)\n" in (out / "summary.txt").read_text()
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
    assert "does not fit chessboard views 0, " in stderr and "rig calibrated" in stderr
    report = json.loads((out / "rig_calibration.json").read_text())
    assert report["ok"] and report["cache_check"]["fits"] is False
    assert report["cache_check"]["bound_px"] == MAX_FIT_PX  # not 2.5 x 5.0 px
    assert max(max(pair) for pair in report["cache_check"]["check_rms_px"]) > MAX_FIT_PX
    assert json.loads((out / "result.json").read_text())["robot_time_s"]["rig"] > 1.5
    assert "rig: calibrated in this run\n" in (out / "summary.txt").read_text()
    stored = load_rig(cached)  # replaced by this run's calibration
    assert stored.rms > 0.0 and abs(stored.K_left[0, 0] - 1400.0) < 1.0
    assert np.allclose(stored.K_left, load_rig(out / "rig.json").K_left)


@pytest.mark.slow
def test_a_rig_calibrated_for_the_cache_names_its_check_view_and_later_runs_capture_two(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    _, serial, cache, cached = stereo_cache(tmp_path)
    code, _, stderr = run_cli(capsys, "calibrate", "--robot", "sim", "--out",
                              str(tmp_path / "first"), "--rig-cache", str(cache),
                              "--no-report", "--no-push")
    assert code == 0 and "rig calibrated" in stderr, stderr
    stored = json.loads(cached.read_text())[CHECK_VIEW_KEY]
    view = stored["view"]
    # the default world's best view shows a x1.01 focal error above the bound
    assert view >= 1 and stored["focal_signal_px"] > fit_bound(load_rig(cached))
    calibration = json.loads((tmp_path / "first" / "rig_calibration.json").read_text())
    assert calibration[CHECK_VIEW_KEY] == stored
    assert CHECK_VIEW_KEY not in json.loads((tmp_path / "first" / "rig.json").read_text())

    out = tmp_path / "reused"
    code, _, stderr = run_cli(capsys, "calibrate", "--robot", "sim", "--out", str(out),
                              "--rig-cache", str(cache), "--no-report", "--no-push")
    assert code == 0, stderr
    assert f"rig: cached for camera {serial}" in stderr and "rig calibrated" not in stderr
    assert f"2-capture check (view {view}, the cache's check view)" in stderr, stderr
    assert json.loads((out / "result.json").read_text())["robot_time_s"]["rig"] == \
        pytest.approx(0.2)
    check = json.loads((out / "rig_calibration.json").read_text())
    assert check["fits"] and check["check_views"] == [0, view] and check["captures"] == 2
    assert check["focal_signal_px"] >= check["bound_px"]
    assert f"rig: cached {cached} (2-capture check)\n" in (out / "summary.txt").read_text()

    # both focal lengths 1 % off (a changed focus both cameras share), the check view kept:
    # the 2 views show it, the run calibrates anew and stores a rig with a check view again
    save_rig(focal_scaled(load_rig(cached), 1.01), cached, {CHECK_VIEW_KEY: stored})
    out = tmp_path / "focus"
    code, _, stderr = run_cli(capsys, "calibrate", "--robot", "sim", "--out", str(out),
                              "--rig-cache", str(cache), "--no-report", "--no-push")
    assert code == 0, stderr
    assert f"does not fit chessboard views 0, {view}:" in stderr and "rig calibrated" in stderr
    report = json.loads((out / "rig_calibration.json").read_text())
    assert report["cache_check"]["captures"] == 2 and report["cache_check"]["fits"] is False
    assert load_rig(cached).K_left[0, 0] == pytest.approx(1400.0, abs=1.0)
    assert json.loads(cached.read_text())[CHECK_VIEW_KEY]["view"] >= 1


def test_a_cache_file_names_a_check_view_the_controller_has_or_none() -> None:
    """load_cached: no check view (an older file) is None; one outside 1..max_views-1, or
    not a number, makes the file unusable (the run then calibrates anew)."""
    import tempfile

    scenario = default_sim_scenario(method="stereo_target")
    with tempfile.TemporaryDirectory() as folder:
        path = truth_rig_file(scenario, Path(folder) / "rig.json")
        rig, view = load_cached(path, 80)
        assert view is None and rig.K_left[0, 0] == pytest.approx(1400.0)
        for entry, expected in (({"view": 3, "focal_signal_px": 0.3}, 3), ({"view": 79}, 79)):
            save_rig(rig, path, {CHECK_VIEW_KEY: entry})
            assert load_cached(path, 80)[1] == expected
        bad: tuple[Any, ...] = ({"view": 0}, {"view": 80}, {"view": "3"}, {"view": True}, 3, {})
        for wrong in bad:
            save_rig(rig, path, {CHECK_VIEW_KEY: wrong})
            with pytest.raises(InputError, match=CHECK_VIEW_KEY):
                load_cached(path, 80)


def test_the_focal_signal_is_what_a_shared_focal_error_shows_in_a_rendered_view() -> None:
    """focal_signal (noise-free, from the view's pose) against a x1.01 rig's RMS on the
    simulator's rendered corners of the same view: equal within the corner noise; a board
    nearly facing the camera shows less than a tilted one (default world: view 4 is tilted
    1 deg, view 9 31 deg)."""
    import tempfile

    scenario = default_sim_scenario(method="stereo_target")
    camera = StereoCamera(Scenario.model_validate(scenario))
    board = scenario["chessboard"]
    spec = ChessboardSpec(int(board["cols"]), int(board["rows"]), float(board["square_size"]))
    with tempfile.TemporaryDirectory() as folder:
        rig = load_rig(truth_rig_file(scenario, Path(folder) / "rig.json"))
    bad = focal_scaled(rig, 1.01)
    signals = {}
    for view in (9, 4):
        left, right = (find_chessboard(image, spec)
                       for image in camera.render("chessboard", view, lambda: np.eye(4)))
        assert left is not None and right is not None
        signals[view] = focal_signal(rig, spec.object_points(), left)
        noise = max(view_fit(rig, spec.object_points(), left, right))
        shown = max(view_fit(bad, spec.object_points(), left, right))
        assert noise < 0.06 and abs(shown - signals[view]) < noise, (view, shown, signals)
    assert signals[9] > 1.5 * signals[4]


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

    stored = json.loads(cached.read_text())
    stored[CHECK_VIEW_KEY] = {"view": 500}  # an edited check view: no such chessboard view
    cached.write_text(json.dumps(stored))
    out = tmp_path / "edited"
    code, _, stderr = run_cli(capsys, "calibrate", "--robot", "sim", "--out", str(out),
                              "--rig-cache", str(cache), "--no-report", "--no-push")
    assert code == 0, stderr
    assert f"{CHECK_VIEW_KEY}: expected a chessboard view 1..79" in stderr, stderr
    assert "the cached rig is unusable" in stderr and "rig calibrated" in stderr
    assert json.loads(cached.read_text())[CHECK_VIEW_KEY]["view"] in range(1, 80)

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
def test_a_check_view_that_shows_too_little_now_gets_views_added(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """World seed 3 stands for a station whose board poses changed since its rig was stored
    (or an edited file): a x1.01 focal error would show only 0.034 px at the cached check
    view 6, and 0.045 px at view 0, below the bound 0.075 px; the check adds view 1 (0.106
    px). The true rig fits on 3 captures; both focal lengths x1.01 are caught."""
    scenario = default_sim_scenario(method="stereo_target")
    scenario["seed"] = 3
    world = tmp_path / "world.json"
    world.write_text(json.dumps(scenario))
    _, _, cache, cached = stereo_cache(tmp_path)
    rig = dataclasses.replace(load_rig(truth_rig_file(scenario, cached)), rms=0.03)
    save_rig(rig, cached, {CHECK_VIEW_KEY: {"view": 6}})
    out = tmp_path / "true"
    code, _, stderr = run_cli(capsys, "calibrate", "--robot", "sim", "--scenario", str(world),
                              "--out", str(out), "--rig-cache", str(cache), "--no-report",
                              "--no-push")
    assert code == 0, stderr
    assert "3-capture check (view 6, the cache's check view, shows too little: views 1 " \
        "added)" in stderr, stderr
    check = json.loads((out / "rig_calibration.json").read_text())
    assert check["fits"] and check["check_views"] == [0, 6, 1]
    assert check["focal_signal_px"] >= check["bound_px"]
    assert json.loads((out / "result.json").read_text())["robot_time_s"]["rig"] == \
        pytest.approx(0.3)

    save_rig(focal_scaled(rig, 1.01), cached, {CHECK_VIEW_KEY: {"view": 6}})
    out = tmp_path / "focus"
    code, _, stderr = run_cli(capsys, "calibrate", "--robot", "sim", "--scenario", str(world),
                              "--out", str(out), "--rig-cache", str(cache), "--no-report",
                              "--no-push")
    assert code == 0, stderr
    assert "does not fit chessboard views 0, 6, 1:" in stderr and "rig calibrated" in stderr


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


def test_worlds_that_share_a_views_seed_show_the_same_board_poses() -> None:
    """The simulator's chessboard.views_seed: a station that shows its camera the same board
    poses robot after robot (bench_robot_time's station worlds); without it each world's
    seed draws its own, as before."""
    def poses(seed: int, views_seed: int | None) -> np.ndarray:
        scenario = default_sim_scenario(method="stereo_target")
        scenario["seed"] = seed
        if views_seed is not None:
            scenario["chessboard"] = {**scenario["chessboard"], "views_seed": views_seed}
        camera = StereoCamera(Scenario.model_validate(scenario))
        return np.concatenate([camera.chessboard_poses(), camera.extra_chessboard_poses()])

    assert np.array_equal(poses(201, 200), poses(202, 200))
    assert np.array_equal(poses(200, 200), poses(200, None))  # its own seed: as before
    assert not np.allclose(poses(201, None), poses(202, None))
