"""`hostpc camera serve`: file cameras served over real loopback sockets to the real
transport client, in-process and as a subprocess (the command a station runs)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from hostpc.sensors.camera_service import CameraService
from hostpc.sensors.stereo_camera import StereoCamera
from hostpc.transport import ControllerClient, ControllerRefusedError
from tests.hostpc.test_sensors import noise_images, write_sequence

TOKEN = "camera-test-token"
ROOT = Path(__file__).resolve().parents[2]


async def test_service_serves_pairs_and_refuses_frozen(tmp_path: Path) -> None:
    left, right = noise_images(4, 21), noise_images(4, 22)
    right[3] = right[2].copy()  # frozen on the fourth capture
    camera = StereoCamera(write_sequence(tmp_path, "left", left),
                          write_sequence(tmp_path, "right", right))
    service = CameraService(camera, TOKEN, {"target": {"radius": 0.01}})
    server = await service.start("127.0.0.1", 0)
    port = server.sockets[0].getsockname()[1]
    try:
        client = await ControllerClient.connect("127.0.0.1", port, token=TOKEN)
        try:
            for k, encoding in enumerate(("raw", "png", "raw")):
                got_left, got_right, q, t = await client.capture("target", encoding=encoding)
                assert np.array_equal(got_left, left[k]) and np.array_equal(got_right, right[k])
                assert q.size == 0 and np.isfinite(t)
            state = await client.state()
            assert state.camera["image_width"] == 64 and state.camera["image_height"] == 48
            assert state.camera["target"] == {"radius": 0.01} and state.q.size == 0
            with pytest.raises(ControllerRefusedError, match="frozen frame") as info:
                await client.capture("target")
            assert info.value.reason == "camera"
            with pytest.raises(ControllerRefusedError) as info:
                await client.move_joints(np.zeros(6), 0.5)
            assert info.value.reason == "unsupported"
            await client.state()  # still serving
        finally:
            await client.close()
    finally:
        server.close()
        await server.wait_closed()
        camera.close()


async def test_service_refuses_wrong_token(tmp_path: Path) -> None:
    from hostpc.errors import ZerocalError

    camera = StereoCamera(write_sequence(tmp_path, "left", noise_images(1, 23)),
                          write_sequence(tmp_path, "right", noise_images(1, 24)))
    server = await CameraService(camera, TOKEN).start("127.0.0.1", 0)
    port = server.sockets[0].getsockname()[1]
    try:
        with pytest.raises(ZerocalError):
            client = await ControllerClient.connect("127.0.0.1", port, token="not-the-token")
            try:
                await client.capture("target")
            finally:
                await client.close()
    finally:
        server.close()
        await server.wait_closed()
        camera.close()


async def test_camera_serve_command(tmp_path: Path) -> None:
    left, right = noise_images(2, 25), noise_images(2, 26)
    args = [sys.executable, "-m", "hostpc.cli.main", "camera", "serve", "--port", "0",
            "--token", TOKEN, "--left", write_sequence(tmp_path, "left", left),
            "--right", write_sequence(tmp_path, "right", right)]
    process = subprocess.Popen(args, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                               text=True, env={**os.environ, "PYTHONPATH": str(ROOT)})
    try:
        assert process.stdout is not None
        line = process.stdout.readline()
        assert line.startswith("serving stereo camera on 127.0.0.1:"), line
        port = int(line.strip().rsplit(":", 1)[1])
        client = await ControllerClient.connect("127.0.0.1", port, token=TOKEN)
        try:
            got_left, got_right, _, _ = await client.capture("chessboard", 3)
            assert np.array_equal(got_left, left[0]) and np.array_equal(got_right, right[0])
        finally:
            await client.close()
        process.send_signal(signal.SIGTERM)
        _, stderr = process.communicate(timeout=20)
        assert process.returncode == 0, stderr
        assert "capture 0: skew" in stderr
    finally:
        if process.poll() is None:
            process.kill()
            process.communicate()


def test_camera_serve_missing_right_exit_3(tmp_path: Path) -> None:
    cv2.imwrite(str(tmp_path / "left_0000.png"), noise_images(1, 27)[0])
    result = subprocess.run(
        [sys.executable, "-m", "hostpc.cli.main", "camera", "serve", "--port", "0",
         "--left", str(tmp_path / "left_%04d.png"), "--right", str(tmp_path / "right.mkv")],
        cwd=ROOT, capture_output=True, text=True, timeout=60,
        env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert result.returncode == 3
    assert result.stderr.strip().splitlines() == [
        f"hostpc camera: error: right camera: '{tmp_path}/right.mkv' does not open "
        "(no such file)"]
