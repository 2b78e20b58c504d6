"""Rig file round trip and errors, poor-calibration flags, `hostpc stereo-calibrate`."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from controller_stub.scenario.spec import Scenario
from controller_stub.world.simulation import Simulation
from hostpc.cli.main import main
from hostpc.errors import InputError
from hostpc.vision import (
    ChessboardSpec,
    StereoRig,
    calibrate_rig,
    load_image_pairs,
    load_rig,
    save_rig,
)

BOARD = ChessboardSpec(9, 6, 0.025)


def _rig() -> StereoRig:
    K = np.array([[1400.0, 0.0, 640.0], [0.0, 1401.0, 512.0], [0.0, 0.0, 1.0]])
    R = cv2.Rodrigues(np.array([0.001, -0.004, 0.002]))[0]
    return StereoRig((1280, 1024), K, [-0.08, 0.05, 4e-4, -3e-4, 0.0], K, [0.0] * 5, R,
                     [-0.12, 1e-4, 5e-4], rms=0.03, n_views=20)


@pytest.fixture(scope="module")
def chessboard_pairs() -> list[tuple[np.ndarray, np.ndarray]]:
    """Six rendered chessboard pairs of the default scenario."""
    sim = Simulation(Scenario())
    return [(f.left, f.right) for f in (sim.capture_stereo("chessboard", k) for k in range(6))]


def test_rig_round_trip(tmp_path: Path) -> None:
    rig = _rig()
    path = tmp_path / "rig.json"
    save_rig(rig, path)
    back = load_rig(path)
    assert back.fingerprint() == rig.fingerprint()
    assert back.image_size == (1280, 1024) and back.n_views == 20 and back.rms == 0.03
    assert back.baseline == pytest.approx(np.linalg.norm([-0.12, 1e-4, 5e-4]))
    np.testing.assert_allclose(back.T_left_right[:3, 3], -rig.R.T @ rig.T)
    with pytest.raises(ValueError):
        back.K_left[0, 0] = 1.0  # read-only


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (lambda d: d.pop("K_left"), "K_left: missing"),
        (lambda d: d.update(K_right=[[1, 2], [3, 4]]), "K_right: expected shape"),
        (lambda d: d.update(T=[0, 0, 0]), "T: zero baseline"),
        (lambda d: d.update(R=np.diag([1, 1, -1]).tolist()), "R: not a rotation"),
        (lambda d: d.update(dist_left=[1, 2, 3]), "dist_left"),
        (lambda d: d.update(format="other"), "format"),
        (lambda d: d.update(version=7), "version"),
        (lambda d: d.update(image_size=[1280.5, 1024]), "image_size"),
        (lambda d: d.update(rms="low"), "rms"),
        (lambda d: d.update(T=["a", 0, 0]), "T: not a numeric"),
    ],
)
def test_rig_file_errors_name_file_and_field(tmp_path: Path, edit, message: str) -> None:  # type: ignore[no-untyped-def]
    data = _rig().to_dict()
    edit(data)
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(data))
    with pytest.raises(InputError, match=message) as info:
        load_rig(path)
    assert str(path) in str(info.value) and "\n" not in str(info.value)


def test_rig_file_unreadable(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="cannot read"):
        load_rig(tmp_path / "missing.json")
    (tmp_path / "broken.json").write_text("{not json")
    with pytest.raises(InputError, match="not valid JSON"):
        load_rig(tmp_path / "broken.json")


def test_too_few_views_flagged(chessboard_pairs: list) -> None:
    result = calibrate_rig(chessboard_pairs, BOARD)
    assert not result.ok
    assert any("usable views" in w for w in result.warnings)
    assert result.used_views == list(range(6))


def test_corners_detected_by_the_caller_give_the_same_rig(chessboard_pairs: list) -> None:
    """calibrate_rig(pairs, board, corners): the caller's detections (the view planner's)
    are used instead of detecting again, with the same result; a view without corners is
    skipped as when detected here."""
    from hostpc.vision.rig_calibration import find_chessboard

    pairs = list(chessboard_pairs)
    corners = [(find_chessboard(left, BOARD), find_chessboard(right, BOARD))
               for left, right in pairs]
    corners[2] = (None, corners[2][1])
    detected = calibrate_rig(pairs[:2] + [(np.full_like(pairs[2][0], 120), pairs[2][1])]
                             + pairs[3:], BOARD)
    given = calibrate_rig(pairs, BOARD, corners)
    assert given.used_views == detected.used_views == [0, 1, 3, 4, 5]
    # bit for bit: calibrate_rig runs OpenCV on one thread (its multi-threaded sums varied)
    np.testing.assert_array_equal(given.rig.K_left, detected.rig.K_left)
    np.testing.assert_array_equal(given.rig.T, detected.rig.T)
    assert given.rms == detected.rms


def test_bad_images_skipped_and_flagged(chessboard_pairs: list) -> None:
    blank = np.full_like(chessboard_pairs[0][0], 120)
    pairs = list(chessboard_pairs)
    pairs[1] = (pairs[1][0], blank)
    pairs[4] = (blank, blank)
    result = calibrate_rig(pairs, BOARD)
    assert not result.ok
    assert [k for k, _ in result.skipped_views] == [1, 4]
    assert "right image" in result.skipped_views[0][1]
    assert result.used_views == [0, 2, 3, 5]
    with pytest.raises(InputError, match="only 2 of"):
        calibrate_rig([pairs[0], pairs[1], pairs[4], pairs[2]], BOARD)


def test_calibration_input_errors(chessboard_pairs: list) -> None:
    with pytest.raises(InputError, match="no image pairs"):
        calibrate_rig([], BOARD)
    left, right = chessboard_pairs[0]
    with pytest.raises(InputError, match="differ in size"):
        calibrate_rig([(left, right[:500])], BOARD)
    with pytest.raises(InputError, match="uint8"):
        calibrate_rig([(left.astype(np.float32), right)], BOARD)
    with pytest.raises(ValueError):
        ChessboardSpec(2, 6, 0.025)


def _write_pairs(folder: Path, pairs: list) -> None:
    folder.mkdir()
    for k, (left, right) in enumerate(pairs):
        cv2.imwrite(str(folder / f"left_{k:02d}.png"), left)
        cv2.imwrite(str(folder / f"right_{k:02d}.png"), right)


def test_cli_poor_calibration_exits_2_unless_accepted(
    tmp_path: Path, chessboard_pairs: list, capsys: pytest.CaptureFixture[str]
) -> None:
    images = tmp_path / "images"
    _write_pairs(images, chessboard_pairs)
    assert [key for key, _, _ in load_image_pairs(images)] == [f"{k:02d}" for k in range(6)]
    out = tmp_path / "rig.json"
    args = ["stereo-calibrate", "--images", str(images), "--board", "9x6", "--square",
            "0.025", "--out", str(out)]
    assert main(args) == 2
    captured = capsys.readouterr()
    assert "RMS reprojection error" in captured.out and "baseline" in captured.out
    assert "WARNING: only 6 usable views" in captured.out
    assert "poor calibration not saved" in captured.err and "--accept-poor" in captured.err
    assert not out.exists()
    assert main([*args, "--accept-poor", "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["ok"] is False and info["saved"] == str(out)
    assert info["baseline_m"] == pytest.approx(0.12, abs=1e-3)
    assert load_rig(out).n_views == 6


def test_cli_bad_input_is_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    base = ["stereo-calibrate", "--out", str(tmp_path / "rig.json")]
    cases = [
        (["--images", str(tmp_path / "none"), "--board", "9x6", "--square", "0.025"],
         "not a folder"),
        (["--images", str(tmp_path), "--board", "9by6", "--square", "0.025"], "--board"),
        (["--images", str(tmp_path), "--board", "9x6", "--square", "25mm"], "--square"),
        (["--images", str(tmp_path), "--board", "9x6", "--square", "0.025"], "no left_"),
    ]
    for extra, message in cases:
        assert main(base + extra) == 2
        err = capsys.readouterr().err
        assert message in err and err.count("\n") == 1, err
    (tmp_path / "left_07.png").write_bytes(b"")
    assert main(base + ["--images", str(tmp_path), "--board", "9x6", "--square", "0.025"]) == 2
    assert "no matching right_07" in capsys.readouterr().err
    (tmp_path / "right_07.png").write_bytes(b"not a png")
    assert main(base + ["--images", str(tmp_path), "--board", "9x6", "--square", "0.025"]) == 2
    assert "cannot read image" in capsys.readouterr().err
