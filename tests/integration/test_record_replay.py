"""Record and replay, and the host cameras against the simulator (hostpc.sensors).

One simulated stereo_target run is recorded (`--record`: every robot call, the raw image
pairs as PNG sequences, joint readings and timestamps). Then
  - `--replay` runs the whole pipeline again from it, without a robot: the same dataset,
    byte for byte;
  - the recorded PNG sequences are played back as camera sources through
    cv2.VideoCapture (`--camera-left/right left_%04d.png`) against a fresh simulator with
    the same scenario and planning seed: the robot is moved to the same poses, each pose
    gets the image rendered there, and the fitted offsets agree with the simulator's own
    capture path within 1e-6 deg.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import pytest

from hostpc.cli.main import main

RUN_ARGS = ("calibrate", "--robot", "sim", "--poses", "10", "--verify-poses", "0",
            "--candidates", "200", "--seed", "3", "--no-push", "--no-report")


@pytest.fixture(scope="module")
def recorded(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The run folder of a recorded simulated run (recording in RUN/recording)."""
    run = tmp_path_factory.mktemp("recorded") / "run"
    assert main([*RUN_ARGS, "--out", str(run), "--record"]) == 0
    return run


def joint_offsets_deg(run: Path) -> dict[str, float]:
    parameters: dict[str, Any] = json.loads((run / "fit.json").read_text())["parameters"]
    return {name: math.degrees(p["value"]) for name, p in parameters.items()
            if name.startswith("joint_offsets.") and not p.get("fixed")}


def test_recording_holds_pairs_joints_and_timestamps(recorded: Path) -> None:
    folder = recorded / "recording"
    header = json.loads((folder / "recording.json").read_text())
    assert header["format"] == "zerocal-recording/1" and header["settings"]["seed"] == 3
    tape = [json.loads(line) for line in (folder / "tape.jsonl").read_text().splitlines()]
    captures = [e for e in tape if e["call"] == "capture"]
    assert [e["result"]["frame"] for e in captures] == list(range(len(captures)))
    assert len([e for e in captures if e["args"]["pattern"] == "target"]) == 10
    assert all(len(e["result"]["q"]) == 6 and "t" in e["result"] for e in captures)
    for e in captures:
        for camera in ("left", "right"):
            assert (folder / f"{camera}_{e['result']['frame']:04d}.png").is_file()


def test_replay_reproduces_the_recorded_dataset_exactly(recorded: Path,
                                                        tmp_path: Path) -> None:
    out = tmp_path / "replayed"
    assert main(["calibrate", "--replay", str(recorded / "recording"), "--out", str(out),
                 "--no-report"]) == 0
    assert (out / "dataset.json").read_bytes() == (recorded / "dataset.json").read_bytes()
    assert (out / "rig.json").read_bytes() == (recorded / "rig.json").read_bytes()
    assert joint_offsets_deg(out) == joint_offsets_deg(recorded)


def test_file_cameras_against_the_simulator_match_its_capture_path(recorded: Path,
                                                                   tmp_path: Path) -> None:
    folder = recorded / "recording"
    out = tmp_path / "files"
    assert main([*RUN_ARGS, "--out", str(out),
                 "--camera-left", str(folder / "left_%04d.png"),
                 "--camera-right", str(folder / "right_%04d.png")]) == 0
    ours, theirs = joint_offsets_deg(out), joint_offsets_deg(recorded)
    assert ours.keys() == theirs.keys() and len(ours) >= 5
    for name in ours:
        assert abs(ours[name] - theirs[name]) < 1e-6, name
    timing = [json.loads(line)
              for line in (out / "camera_timing.jsonl").read_text().splitlines()]
    assert len(timing) == len(list(folder.glob("left_*.png")))
    assert all(math.isfinite(t["skew_s"]) for t in timing)


def test_replay_with_other_settings_diverges_in_one_line(recorded: Path, tmp_path: Path,
                                                         capsys: pytest.CaptureFixture[str]
                                                         ) -> None:
    folder = tmp_path / "edited"
    folder.mkdir()
    for path in (recorded / "recording").iterdir():
        (folder / path.name).symlink_to(path)
    header = json.loads((recorded / "recording" / "recording.json").read_text())
    header["settings"]["seed"] = 4  # another plan than the one recorded
    (folder / "recording.json").unlink()
    (folder / "recording.json").write_text(json.dumps(header))
    code = main(["calibrate", "--replay", str(folder), "--out", str(tmp_path / "o"),
                 "--no-report"])
    err = capsys.readouterr().err
    assert code == 2
    errors = [line for line in err.splitlines() if not line.startswith("[")
              and not line.startswith(("plan:", "note:", "rig", "joints:"))]
    assert len(errors) == 1 and "but the recording holds" in errors[0], err


def test_frozen_camera_stops_calibrate_in_one_line(tmp_path: Path,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    from tests.hostpc.test_sensors import noise_images, write_sequence

    left = noise_images(3, 31)
    left[1] = left[0].copy()  # the left camera freezes on the second capture
    code = main([*RUN_ARGS, "--out", str(tmp_path / "run"),
                 "--camera-left", write_sequence(tmp_path, "left", left),
                 "--camera-right", write_sequence(tmp_path, "right", noise_images(3, 32))])
    err = capsys.readouterr().err
    assert code == 3
    errors = [line for line in err.splitlines() if line.startswith("hostpc calibrate: error")]
    assert len(errors) == 1 and "left camera: frozen frame (capture 1" in errors[0], err


def test_replay_refuses_options_that_change_the_recorded_run(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code = main(["calibrate", "--replay", str(tmp_path / "recording"), "--out",
                 str(tmp_path / "rep"), "--poses", "25", "--effects", "+backlash",
                 "--no-report"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1
    assert "exactly as recorded" in err[0] and "--poses" in err[0] and "--effects" in err[0]
    assert "--out" not in err[0].split("drop", 1)[1]  # --out and --no-report are fine
    assert not (tmp_path / "rep").exists()


def test_dual_loop_replay_keeps_the_pixels_and_the_camera_calibration(tmp_path: Path) -> None:
    """A recorded dual_loop run replays to the same dataset, byte for byte, with each
    target's pixels and the head camera's calibration block (docs/vision.md 3.4)."""
    run, out = tmp_path / "run", tmp_path / "replayed"
    args = ("calibrate", "--robot", "sim", "--method", "dual_loop", "--poses", "12",
            "--verify-poses", "0", "--candidates", "100", "--seed", "2", "--no-push",
            "--no-report")
    assert main([*args, "--out", str(run), "--record"]) == 0
    assert main(["calibrate", "--replay", str(run / "recording"), "--out", str(out),
                 "--no-report"]) == 0
    assert (out / "dataset.json").read_bytes() == (run / "dataset.json").read_bytes()
    document = json.loads((run / "dataset.json").read_text())
    assert all(len(sample["uv"]) == 2 for sample in document["samples"])
    assert len(document["rig_uncertainty"]["covariance"]) == 24
