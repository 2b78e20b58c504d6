"""Host cameras (hostpc.sensors) on real files through cv2.VideoCapture: pairs, timing,
frozen and missing cameras; the recording tape fed broken input; the CLI's one-line errors."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from hostpc.cli.main import main
from hostpc.errors import InputError
from hostpc.sensors.recording import RECORDING_FORMAT, ReplayAdapter, ReplayDiverged
from hostpc.sensors.sources import CameraError, parse_source
from hostpc.sensors.stereo_camera import StereoCamera


def write_sequence(folder: Path, camera: str, images: list[np.ndarray]) -> str:
    """Write images as camera_%04d.png in folder; returns the pattern."""
    folder.mkdir(parents=True, exist_ok=True)
    for k, image in enumerate(images):
        assert cv2.imwrite(str(folder / f"{camera}_{k:04d}.png"), image)
    return str(folder / f"{camera}_%04d.png")


def noise_images(n: int, seed: int, shape: tuple[int, int] = (48, 64)) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    return [rng.integers(0, 256, shape, dtype=np.uint8) for _ in range(n)]


def test_parse_source_kinds() -> None:
    assert parse_source("0").kind == "device" and parse_source("0").target == 0
    assert parse_source("/dev/video2").kind == "v4l2"
    assert parse_source("v4l2src device=/dev/video0 ! videoconvert ! appsink").kind == \
        "gstreamer"
    assert parse_source("left_%04d.png").kind == "sequence"
    assert parse_source("session.mkv").kind == "file"
    assert parse_source("0").live and not parse_source("left_%04d.png").live


def test_sequence_pairs_are_the_written_images(tmp_path: Path) -> None:
    left, right = noise_images(4, 1), noise_images(4, 2)
    with StereoCamera(write_sequence(tmp_path, "left", left),
                      write_sequence(tmp_path, "right", right), max_skew_s=1e-9) as camera:
        for k in range(4):
            pair = camera.capture()
            assert pair.index == k
            assert np.array_equal(pair.left, left[k]) and np.array_equal(pair.right, right[k])
            assert pair.left.dtype == np.uint8 and pair.left.ndim == 2
            assert np.isfinite(pair.skew_s) and pair.t_right >= pair.t_left
        with pytest.raises(CameraError, match="left camera: no frame"):
            camera.capture()


def write_video(path: Path, images: list[np.ndarray]) -> Path:
    """A lossless (FFV1) grey video of `images` at 10 fps."""
    height, width = images[0].shape
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"FFV1"), 10.0, (width, height),
                             False)
    if not writer.isOpened():
        pytest.skip("this OpenCV cannot write FFV1 video")
    for image in images:
        writer.write(image)
    writer.release()
    return path


def test_video_files_pair_exactly_with_media_timestamps(tmp_path: Path) -> None:
    left, right = noise_images(3, 14), noise_images(3, 15)
    with StereoCamera(str(write_video(tmp_path / "left.mkv", left)),
                      str(write_video(tmp_path / "right.mkv", right))) as camera:
        assert camera.refused_controls == {}
        stamps = []
        for k in range(3):
            pair = camera.capture()
            assert np.array_equal(pair.left, left[k]) and np.array_equal(pair.right, right[k])
            stamps.append(pair.stamp_left)
        assert stamps == pytest.approx([0.0, 0.1, 0.2])


def test_controls_a_file_backend_refuses_are_reported(tmp_path: Path) -> None:
    with StereoCamera(write_sequence(tmp_path, "left", noise_images(2, 16)),
                      write_sequence(tmp_path, "right", noise_images(2, 17)),
                      exposure=100.0, gain=2.0) as camera:
        assert camera.refused_controls == {"left": ["exposure", "gain"],
                                           "right": ["exposure", "gain"]}
        camera.capture()


def test_discard_drops_pairs_before_each_capture(tmp_path: Path) -> None:
    left, right = noise_images(4, 12), noise_images(4, 13)
    with StereoCamera(write_sequence(tmp_path, "left", left),
                      write_sequence(tmp_path, "right", right), discard=1) as camera:
        assert camera.discard == 1
        assert np.array_equal(camera.capture().left, left[1])
        assert np.array_equal(camera.capture().right, right[3])


def test_frozen_frame_refused(tmp_path: Path) -> None:
    left = noise_images(3, 3)
    right = noise_images(3, 4)
    right[2] = right[1].copy()  # the right camera hangs on its last image
    with StereoCamera(write_sequence(tmp_path, "left", left),
                      write_sequence(tmp_path, "right", right)) as camera:
        camera.capture()
        camera.capture()
        with pytest.raises(CameraError, match="right camera: frozen frame") as info:
            camera.capture()
    assert "\n" not in str(info.value) and info.value.exit_code == 3


def test_timestamp_that_does_not_advance_refused(tmp_path: Path) -> None:
    with StereoCamera(write_sequence(tmp_path, "left", noise_images(1, 5)),
                      write_sequence(tmp_path, "right", noise_images(1, 6))) as camera:
        images = noise_images(2, 7)
        camera._check_fresh(0, "left", images[0], 12.5)
        with pytest.raises(CameraError, match="left camera: stale frame"):
            camera._check_fresh(0, "left", images[1], 12.5)


@pytest.mark.parametrize("right", ["missing_%04d.png", "missing.mkv", "/dev/video63", "63"])
def test_right_camera_that_does_not_open(tmp_path: Path, right: str) -> None:
    left = write_sequence(tmp_path, "left", noise_images(2, 8))
    with pytest.raises(CameraError, match="right camera: .* does not open"):
        StereoCamera(left, str(tmp_path / right) if "video" not in right and right != "63"
                     else right)


def run_cli(capsys: pytest.CaptureFixture[str], *args: str) -> tuple[int, str, str]:
    code = main(list(args))
    out, err = capsys.readouterr()
    return code, out, err


def test_camera_check_cli(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    left = write_sequence(tmp_path, "left", noise_images(3, 9))
    right = write_sequence(tmp_path, "right", noise_images(3, 10))
    code, out, err = run_cli(capsys, "camera", "check", "--left", left, "--right", right,
                             "--frames", "3")
    assert code == 0, err
    assert [json.loads(line)["index"] for line in out.splitlines()] == [0, 1, 2]
    assert "skew median" in err
    code, out, err = run_cli(capsys, "camera", "check", "--left", left, "--right",
                             str(tmp_path / "nothing_%04d.png"))
    assert code == 3
    assert err.strip().splitlines() == [
        f"hostpc camera: error: right camera: '{tmp_path}/nothing_%04d.png' does not open "
        "(no image of the sequence numbered 0..4)"]


def error_lines(stderr: str) -> list[str]:
    """The error lines of stderr (progress lines aside)."""
    return [line for line in stderr.splitlines() if not line.startswith("[")]


def test_calibrate_camera_options_one_line(tmp_path: Path,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    left = write_sequence(tmp_path, "left", noise_images(2, 11))
    code, _, err = run_cli(capsys, "calibrate", "--robot", "127.0.0.1:1", "--out",
                           str(tmp_path / "a"), "--camera-left", left)
    assert code == 2
    assert error_lines(err) == ["hostpc calibrate: error: --camera-left and --camera-right "
                                "go together (a stereo pair)"]
    code, _, err = run_cli(capsys, "calibrate", "--robot", "127.0.0.1:1", "--out",
                           str(tmp_path / "b"), "--camera-left", left, "--camera-right",
                           "/dev/video63")
    assert code == 3
    assert error_lines(err) == ["hostpc calibrate: error: right camera: '/dev/video63' does "
                                "not open (v4l2)"]
    code, _, err = run_cli(capsys, "calibrate", "--replay", str(tmp_path), "--out",
                           str(tmp_path / "c"))
    assert code == 2 and len(error_lines(err)) == 1 and "not a recording" in err


def _recording(folder: Path, lines: list[str]) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "recording.json").write_text(json.dumps({"format": RECORDING_FORMAT,
                                                       "settings": {"method": "x"}}))
    (folder / "tape.jsonl").write_text("\n".join(lines) + "\n")
    return folder


async def test_replay_refuses_a_run_that_diverges(tmp_path: Path) -> None:
    entry = {"n": 0, "call": "move_joints", "args": {"q": [0.1, 0.2], "speed": 0.5},
             "result": {"completed": True, "q": [0.1, 0.2], "reason": None}}
    replay = ReplayAdapter(_recording(tmp_path / "ok", [json.dumps(entry)]))
    with pytest.raises(ReplayDiverged, match="call 0 is move_joints"):
        await replay.move_joints(np.array([0.1, 0.2000000000000001]), 0.5)
    replay = ReplayAdapter(_recording(tmp_path / "ok2", [json.dumps(entry)]))
    outcome = await replay.move_joints(np.array([0.1, 0.2]), 0.5)
    assert outcome.completed and outcome.q.tolist() == [0.1, 0.2]
    with pytest.raises(ReplayDiverged, match="after the last of 1 recorded calls"):
        await replay.get_offsets()


def test_replay_refuses_a_broken_tape(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="tape.jsonl line 2 is not valid JSON"):
        ReplayAdapter(_recording(tmp_path / "r", ['{"n": 0}', '{"n": 1, "call"']))
    (tmp_path / "r" / "recording.json").write_text('{"format": "other"}')
    with pytest.raises(InputError, match="is not zerocal-recording/1"):
        ReplayAdapter(tmp_path / "r")
