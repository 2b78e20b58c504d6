"""A RobotAdapter whose stereo captures come from cameras on the host, not the controller.

`hostpc calibrate --camera-left SOURCE --camera-right SOURCE`: the robot adapter still
moves the robot and reads its joints; `capture()` takes the next pair from a
`StereoCamera` and pairs it with the joint angles the robot reports right after the grab
(the methods capture only when a move has completed, so the robot is at rest). Every
capture, whatever its pattern, is the next frame: for rig calibration the operator shows
the chessboard views in order (or gives --rig FILE), a file source holds them in the order
the run asks for them.

The timing of every pair (host grab times, backend timestamps, skew) is appended to
`camera_timing.jsonl` in the run folder.
"""

from __future__ import annotations

import asyncio
import json
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from hostpc.robots.base import (
    ContactOutcome,
    MoveOutcome,
    PairTiming,
    RobotAdapter,
    RobotState,
    StereoCapture,
)
from hostpc.sensors.stereo_camera import StereoCamera, StereoPair

TIMING_FILE = "camera_timing.jsonl"


class HostCameraAdapter:
    """`robot` for motion and joints, `camera` for images. timing_log: file the timing of
    every pair is appended to (None: not logged). Closing closes both. capabilities: the
    robot's, plus this adapter's `last_timing` (a `CaptureTiming`)."""

    def __init__(self, robot: RobotAdapter, camera: StereoCamera,
                 timing_log: Path | None = None) -> None:
        self.robot = robot
        self.camera = camera
        self.timing_log = timing_log
        self.last_timing: PairTiming | None = None
        self._lock = asyncio.Lock()
        self.capabilities = replace(robot.capabilities, capture_timing=self)

    @property
    def driver(self) -> str:
        """The robot's driver (the cameras are this host's)."""
        return self.robot.driver

    async def state(self) -> RobotState:
        return await self.robot.state()

    async def move_joints(self, q: np.ndarray, speed: float) -> MoveOutcome:
        return await self.robot.move_joints(q, speed)

    async def guarded_move(self, q: np.ndarray, speed: float, io_line: int) -> ContactOutcome:
        return await self.robot.guarded_move(q, speed, io_line)

    async def capture(self, pattern: str = "target", view: int = 0) -> StereoCapture:
        """The next pair (left, right (H, W) uint8) with q (n,) rad and the controller time
        (s) the robot reports right after the grab (host clock if it reports none)."""
        async with self._lock:
            pair: StereoPair = await asyncio.to_thread(self.camera.capture)
        state = await self.robot.state()
        t = float(state.extra.get("time", pair.t_left))
        self.last_timing = PairTiming(pair.index, pair.t_left, pair.t_right, pair.stamp_left,
                                      pair.stamp_right, pair.skew_s, t)
        if self.timing_log is not None:
            entry = {"pattern": pattern, "view": view, **self.last_timing.to_json(),
                     "wall": time.time()}
            with self.timing_log.open("a", encoding="utf-8") as out:
                out.write(json.dumps(entry) + "\n")
        return StereoCapture(left=pair.left, right=pair.right, q=np.asarray(state.q, float),
                             t=t)

    async def get_offsets(self) -> np.ndarray:
        return await self.robot.get_offsets()

    async def set_offsets(self, offsets: np.ndarray) -> tuple[np.ndarray, str]:
        return await self.robot.set_offsets(offsets)

    async def rollback(self, rollback_id: str) -> np.ndarray:
        return await self.robot.rollback(rollback_id)

    async def close(self) -> None:
        try:
            await self.robot.close()
        finally:
            self.camera.close()
