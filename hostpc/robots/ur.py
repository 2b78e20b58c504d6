"""RobotAdapter for Universal Robots through the ur_rtde library (`--driver ur`).

    RTDEReceiveInterface   joint angles (getActualQ), digital IO bits, timestamps (500 Hz
                           on e-Series, 125 Hz on CB3)
    RTDEControlInterface   moveJ / stopJ (ur_rtde uploads its control script to 30003);
                           every moveJ is asynchronous, its progress polled, so a
                           cancelled move (Ctrl-C, SIGTERM) is stopped with stopJ
                           (`ur_link.py`); guarded moves for the touch probe are watched
                           sample by sample and stopped on the input edge (`guarded_move`,
                           docs/ur-probe.md)
    RTDEIOInterface        standard digital outputs
    ControllerClient       stereo captures from the camera service (zerocal protocol,
                           `--camera HOST:PORT`, default the robot's host, port 47800)

Two hazards of ur_rtde shape this module (both measured):
1. Its constructors hold the Python GIL while they wait for the controller, so a peer that
   accepts a TCP connection and never answers freezes the whole interpreter, event loop
   included. `connect_ur` therefore first talks to the controller with plain asyncio under
   a timeout (`ur_precheck.py`): an RTDE protocol-version request and controller-version
   request on 30004, the dashboard greeting and queries on 29999, a TCP connect to 30003.
   Only a controller that answered all three gets a ur_rtde interface. Every ur_rtde call
   runs in a worker thread (`asyncio.to_thread`), never on the event loop.
2. Right after a move ends, the receive interface may still hold a sample from before
   the end of the motion. `move_joints` therefore waits for a sample whose RTDE timestamp
   is newer than the one held when the move ended and that is at the target (within
   `SETTLE_TOLERANCE_RAD`, up to `SETTLE_TIMEOUT_S`; `ur_link.py`).

The adapter is composed of collaborators that own their state: `UrLink` (ur_link.py: the
ur_rtde interfaces, samples, moves, the motion lock), `UrHostOffsets` (ur_offsets.py: the
host zero offsets, their rollback ids and the export, the adapter's `OffsetExport`
capability), `UrGuardedMove` (ur_guarded.py: the probe's guarded move and latch timings),
and the pre-checks of `ur_precheck.py` run by `connect_ur`.

Zero offsets: a UR controller offers no way to write joint zero offsets. This adapter applies
them ON THE HOST. With the host offsets `o` (n,) rad (zero at connect unless given):

    command sent to the UR  = wanted - o       (move_joints, guarded_move)
    reported angle          = measured + o     (state, captures, move outcomes)

which is exactly docs/conventions.md's controller zero offset (`q_cmd = encoder + o`) with the
UR's own calibrated angle in the role of the encoder: a fitted `joint_offsets.qi = delta_i`
(`q_true = q_cmd + delta`) is applied by `set_offsets(o + delta)`, after which the adapter
reports true angles (`ur_offsets.py`). The offsets live in this adapter (and in the files
`hostpc.robots.ur_export` writes for ROS / URScript users); the robot itself is unchanged,
and other software driving it must load the exported files to benefit.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
from typing import Any

import numpy as np

from hostpc.errors import ConnectionFailed, ControllerError, InputError
from hostpc.json_object import JsonObject
from hostpc.robots.base import Capabilities, ContactOutcome, MoveOutcome, RobotState, StereoCapture
from hostpc.robots.ur_guarded import N_DIGITAL_IO, LatchTiming, UrGuardedMove, rtde_frequency
from hostpc.robots.ur_link import (
    JOINT_ACCELERATION,
    MAX_JOINT_SPEED,
    SETTLE_S,
    UrLink,
    check_joints,
    joint_velocity,
)
from hostpc.robots.ur_offsets import UrHostOffsets
from hostpc.robots.ur_precheck import UrControllerInfo, check_controller

logger = logging.getLogger(__name__)

CAMERA_PORT = 47800


# ---------------------------------------------------------------------- the adapter


def _limits(robot_name: str) -> tuple[np.ndarray, np.ndarray]:
    """(q_min, q_max) (6,) of the robot library entry, else UR's +-360 deg."""
    from hostpc.kinematics import robots

    if robot_name in robots.names():
        chain = robots.get_robot(robot_name)
        return np.asarray(chain.q_min, float), np.asarray(chain.q_max, float)
    return np.full(6, -2.0 * math.pi), np.full(6, 2.0 * math.pi)


def _bits(word: int, n: int) -> tuple[bool, ...]:
    return tuple(bool(int(word) >> i & 1) for i in range(n))


class UrAdapter:
    """A `RobotAdapter` over ur_rtde's three interfaces (+ a camera client).

    The ur_rtde objects are created by `connect_ur`; tests may pass fakes. offsets: the
    host zero offsets (6,) rad (module docstring). capabilities: `OffsetExport` (the host
    offsets' `export_offsets`): the zero offsets live in this adapter for this session, not
    in the robot, so a push is also written as files for the software that drives the robot.
    """

    driver = "ur"

    def __init__(
        self,
        host: str,
        info: UrControllerInfo,
        receive: Any,
        control: Any,
        io: Any,
        camera: Any | None = None,
        *,
        offsets: np.ndarray | None = None,
        timeout: float = 10.0,
    ) -> None:
        self.host = host
        self.info = info
        self.camera = camera
        self.link = UrLink(host, receive, control, io, timeout)
        self.offsets = UrHostOffsets(host, offsets)
        self.guarded = UrGuardedMove(self.link, self.offsets,
                                     rtde_frequency(info.controller_version))
        self.q_min, self.q_max = _limits(info.robot_name)
        self.capabilities = Capabilities(offset_export=self.offsets)

    @property
    def address(self) -> str:
        """The UR host."""
        return self.host

    @property
    def latches(self) -> list[LatchTiming]:
        """Timing of every probe contact of this session (guarded_move)."""
        return self.guarded.latches

    @property
    def latch_jitter_s(self) -> float:
        """One-sigma timing spread of a latched edge (s), UrGuardedMove.latch_jitter_s."""
        return self.guarded.latch_jitter_s

    def latch_summary(self) -> str | None:
        """One line on the probe latches of this session (None without contacts)."""
        return self.guarded.latch_summary()

    # ---------------------------------------------------------------- RobotAdapter

    async def state(self) -> RobotState:
        """Reported angles (measured + host offsets), limits, IO, camera description."""
        stamp, q, inputs, outputs = await self.link.call(self.link.sample)
        camera: JsonObject = {}
        if self.camera is not None:
            camera_state = await self.camera.state()
            camera = dict(camera_state.camera)
            if isinstance(camera.get("probe"), dict):
                # this driver latches the probe from RTDE samples: at least their spread
                probe = dict(camera["probe"])
                probe["latency_jitter"] = max(float(probe.get("latency_jitter") or 0.0),
                                              self.guarded.latch_jitter_s)
                camera["probe"] = probe
        offsets = self.offsets.values
        return RobotState(
            q=q + offsets,
            zero_offsets=offsets,
            q_min=self.q_min + offsets,
            q_max=self.q_max + offsets,
            digital_inputs=_bits(inputs, N_DIGITAL_IO),
            digital_outputs=_bits(outputs, N_DIGITAL_IO),
            camera=camera,
            robot=self.info.robot_name,
            extra={
                "driver": "ur",
                "time": stamp,
                "controller_version": ".".join(str(v) for v in self.info.controller_version),
                "polyscope": self.info.polyscope,
                "serial_number": self.info.serial_number,
                "offsets_applied_on_host": True,
                # what this driver commands: speed fraction 1 is MAX_JOINT_SPEED, every
                # moveJ ramps at JOINT_ACCELERATION (the host's robot time, robot_time.py)
                "max_joint_speed": [MAX_JOINT_SPEED] * 6,
                "max_joint_acceleration": [JOINT_ACCELERATION] * 6,
                # the rest it waits for before a guarded approach (UrLink.settle)
                "settle_s": SETTLE_S,
            },
        )

    async def move_joints(self, q: np.ndarray, speed: float) -> MoveOutcome:
        """moveJ to the reported angles q (6,) rad; the UR gets q - offsets."""
        target = self.offsets.to_ur(check_joints(q))
        velocity = joint_velocity(speed)
        async with self.link.motion_lock:
            moved = await self.link.move(target, velocity)
        return MoveOutcome(completed=moved.completed, q=self.offsets.reported(moved.q),
                           reason=moved.reason)

    async def guarded_move(self, q: np.ndarray, speed: float, io_line: int) -> ContactOutcome:
        """Guarded move toward the reported angles q (6,) (UrGuardedMove.guarded_move)."""
        return await self.guarded.guarded_move(q, speed, io_line)

    async def capture(self, pattern: str = "target", view: int = 0) -> StereoCapture:
        """Stereo pair from the camera service; q at exposure reported (+ host offsets)."""
        if self.camera is None:
            raise ControllerError("UR driver: no camera service configured (--camera HOST:PORT)")
        left, right, q, t = await self.camera.capture(pattern, view)
        if len(q) == 0:  # a camera service without joints (hostpc camera serve): our q, t
            t, q, _, _ = await self.link.call(self.link.sample)
        return StereoCapture(left=left, right=right,
                             q=self.offsets.reported(np.asarray(q, float)), t=t)

    async def get_offsets(self) -> np.ndarray:
        """The host zero offsets (6,) rad (UrHostOffsets)."""
        return await self.offsets.get_offsets()

    async def set_offsets(self, offsets: np.ndarray) -> tuple[np.ndarray, str]:
        """Replace the host zero offsets, nothing written to the robot (UrHostOffsets)."""
        return await self.offsets.set_offsets(offsets)

    async def rollback(self, rollback_id: str) -> np.ndarray:
        """Restore the host offsets saved under `rollback_id` (UrHostOffsets)."""
        return await self.offsets.rollback(rollback_id)

    async def close(self) -> None:
        """Report the probe latch timing (a warning-level line, so it is always shown),
        stop the control script and disconnect every interface."""
        summary = self.guarded.latch_summary()
        if summary is not None:
            logger.warning("%s", summary)
        await self.link.close()
        if self.camera is not None:
            await self.camera.close()


# ---------------------------------------------------------------------- connecting


def parse_camera(camera: str | tuple[str, int] | None, host: str) -> tuple[str, int] | None:
    """`--camera HOST:PORT` (or PORT, or `none`) -> (host, port); default (host, 47800)."""
    if camera is None:
        return host, CAMERA_PORT
    if isinstance(camera, tuple):
        return str(camera[0]), int(camera[1])
    text = camera.strip()
    if text.lower() in ("none", "off", ""):
        return None
    cam_host, _, port_text = text.rpartition(":")
    if not cam_host:
        cam_host, port_text = (host, text) if text.isdigit() else (text, str(CAMERA_PORT))
    try:
        port = int(port_text)
    except ValueError:
        raise InputError(f"--camera {camera!r}: port {port_text!r} is not a number") from None
    return cam_host.strip("[]"), port


async def connect_ur(
    host: str,
    camera_host: str | None = None,
    camera_port: int = CAMERA_PORT,
    token: str | None = None,
    timeout: float = 10.0,
    *,
    offsets: np.ndarray | list[float] | None = None,
    probe_timeout: float | None = None,
) -> UrAdapter:
    """Connect to the UR at `host` (fixed ports 30004 / 29999 / 30003) and to its camera
    service (`camera_host:camera_port` over the zerocal protocol; camera_host None = no
    camera). The asyncio pre-checks run first (module docstring); ConnectionFailed if any
    fails, before any ur_rtde interface is constructed. InputError if ur_rtde is not
    installed (it has wheels for some Python versions only).
    """
    try:
        import rtde_control
        import rtde_io
        import rtde_receive
    except ModuleNotFoundError as exc:
        raise InputError(f"--driver ur is not available: {exc}") from exc

    from hostpc.transport import ControllerClient

    check_timeout = min(timeout, 5.0) if probe_timeout is None else probe_timeout
    info = await check_controller(host, check_timeout)
    camera: Any = None
    if camera_host is not None:
        camera = await ControllerClient.connect(camera_host, camera_port, token=token,
                                                timeout=timeout)
    receive = control = io = None
    try:
        receive = await asyncio.to_thread(rtde_receive.RTDEReceiveInterface, host,
                                          rtde_frequency(info.controller_version))
        control = await asyncio.to_thread(rtde_control.RTDEControlInterface, host)
        io = await asyncio.to_thread(rtde_io.RTDEIOInterface, host)
    except RuntimeError as exc:
        for interface in (control, io, receive):
            if interface is not None:
                with contextlib.suppress(Exception):
                    await asyncio.to_thread(interface.disconnect)
        if camera is not None:
            await camera.close()
        raise ConnectionFailed(f"UR {host}: ur_rtde could not connect: {exc}") from exc
    adapter = UrAdapter(
        host,
        info,
        receive,
        control,
        io,
        camera,
        offsets=None if offsets is None else np.asarray(offsets, float),
        timeout=timeout,
    )
    logger.info(
        "UR %s connected: %s, PolyScope %s, serial %s", host, info.robot_name, info.polyscope,
        info.serial_number or "?"
    )
    return adapter


async def connect(
    host: str,
    port: int | None = None,
    *,
    timeout: float = 10.0,
    camera: str | tuple[str, int] | None = None,
    token: str,
    offsets: np.ndarray | list[float] | None = None,
) -> UrAdapter:
    """The UR row of the driver table (`hostpc.robots.drivers`).

    The UR ports are fixed (30004 / 29999 / 30003), so the `--robot HOST:PORT` port names
    the camera service's zerocal port instead (default 47800). camera: `HOST:PORT`
    overriding that (`none` for no camera). token: the camera service's token (resolved by
    `open_robot`: --token / $ZEROCAL_TOKEN / the simulator's).
    """
    camera_address = parse_camera(camera if camera is not None else (host, port or CAMERA_PORT),
                                  host)
    return await connect_ur(
        host,
        camera_address[0] if camera_address else None,
        camera_address[1] if camera_address else CAMERA_PORT,
        token,
        timeout,
        offsets=offsets,
    )
