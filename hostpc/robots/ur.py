"""RobotAdapter for Universal Robots through the ur_rtde library (`--driver ur`).

    RTDEReceiveInterface   joint angles (getActualQ), digital IO bits, timestamps (500 Hz
                           on e-Series, 125 Hz on CB3)
    RTDEControlInterface   moveJ / stopJ (ur_rtde uploads its control script to 30003);
                           guarded moves for the touch probe are an asynchronous moveJ
                           watched sample by sample and stopped on the input edge
                           (`guarded_move`, docs/ur-probe.md)
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
2. Right after `moveJ` returns, the receive interface may still hold a sample from before
   the end of the motion. `move_joints` therefore waits for a sample whose RTDE timestamp
   is newer than the one held when moveJ returned and that is at the target (within
   `SETTLE_TOLERANCE_RAD`, up to `SETTLE_TIMEOUT_S`).

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
from collections.abc import Callable
from typing import Any, TypeVar

import numpy as np

from hostpc.errors import ConnectionFailed, ControllerError, InputError, RequestTimeout
from hostpc.robots.base import MoveOutcome, RobotState, StereoCapture
from hostpc.robots.ur_guarded import (
    JOINT_ACCELERATION,
    MAX_JOINT_SPEED,
    N_DIGITAL_IO,
    LatchTiming,
    UrGuardedMoveMixin,
    rtde_frequency,
)
from hostpc.robots.ur_offsets import UrOffsetsMixin
from hostpc.robots.ur_precheck import UrControllerInfo, check_controller

logger = logging.getLogger(__name__)

__all__ = ["CAMERA_PORT", "SETTLE_TIMEOUT_S", "SETTLE_TOLERANCE_RAD", "UrAdapter", "connect",
           "connect_ur", "parse_camera"]

CAMERA_PORT = 47800
SETTLE_TOLERANCE_RAD = 1e-3
SETTLE_TIMEOUT_S = 2.0
T = TypeVar("T")


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


class UrAdapter(UrOffsetsMixin, UrGuardedMoveMixin):
    """A `RobotAdapter` over ur_rtde's three interfaces (+ a camera client).

    The ur_rtde objects are created by `connect_ur`; tests may pass fakes. offsets: the
    host zero offsets (6,) rad (module docstring).
    """

    driver = "ur"
    offsets_on_controller = False
    """The zero offsets live in this adapter for this session, not in the robot (module
    docstring); `export_offsets` writes them for the software that drives the robot."""
    EXPORT_STEM = "ur"
    """Exports are `ur_calibration.yaml`, `ur_joints.urdf.xml`, `ur_offsets.script`."""

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
        self.receive = receive
        self.control = control
        self.io = io
        self.camera = camera
        self.timeout = float(timeout)
        self._offsets = np.zeros(6) if offsets is None else self._check_offsets(offsets)
        self._rollbacks: dict[str, np.ndarray] = {}
        self._rollback_counter = 0
        self._motion_lock = asyncio.Lock()
        self.q_min, self.q_max = _limits(info.robot_name)
        self.rtde_frequency = rtde_frequency(info.controller_version)
        self.latches: list[LatchTiming] = []
        """Timing of every probe contact of this session (guarded_move)."""

    @property
    def address(self) -> str:
        """The UR host."""
        return self.host

    # ---------------------------------------------------------------- helpers

    async def _call(self, function: Callable[..., T], *args: Any) -> T:
        """Run a blocking ur_rtde call in a worker thread; errors -> ControllerError."""
        try:
            return await asyncio.to_thread(function, *args)
        except (RuntimeError, ValueError, TypeError) as exc:
            name = getattr(function, "__name__", "ur_rtde call")
            raise ControllerError(f"UR {self.host}: {name} failed: {exc}") from exc

    def _sample(self) -> tuple[float, np.ndarray, int, int]:
        """(timestamp, actual q (6,), input bits, output bits) of ONE RTDE package: read
        again if the receive thread stored a newer package between the getters."""
        for _ in range(10):
            stamp = float(self.receive.getTimestamp())
            sample = (
                stamp,
                np.asarray(self.receive.getActualQ(), float),
                int(self.receive.getActualDigitalInputBits()),
                int(self.receive.getActualDigitalOutputBits()),
            )
            if float(self.receive.getTimestamp()) == stamp:
                return sample
        return sample

    async def _fresh_q(self, after: float, target: np.ndarray | None) -> np.ndarray:
        """Measured q (6,) from a sample newer than timestamp `after` (and at `target` within
        SETTLE_TOLERANCE_RAD if given, waiting up to SETTLE_TIMEOUT_S for it)."""
        loop = asyncio.get_running_loop()
        deadline = loop.time() + SETTLE_TIMEOUT_S
        fresh: np.ndarray | None = None
        while True:
            stamp, q, _, _ = await self._call(self._sample)
            if stamp > after:
                fresh = q
                if target is None or np.max(np.abs(q - target)) <= SETTLE_TOLERANCE_RAD:
                    return q
            if loop.time() > deadline:
                if fresh is not None:
                    logger.warning("UR %s: robot %.2e rad from the target after the move",
                                   self.host, float(np.max(np.abs(fresh - target))))
                    return fresh
                raise RequestTimeout(
                    f"UR {self.host}: no new RTDE sample within {SETTLE_TIMEOUT_S:.1f} s"
                )
            await asyncio.sleep(0.002)

    def _check_q(self, q: np.ndarray | list[float], name: str = "q") -> np.ndarray:
        values = np.asarray(q, dtype=float).reshape(-1)
        if values.shape != (6,) or not np.all(np.isfinite(values)):
            raise InputError(f"{name}: expected 6 finite joint angles (rad), got {values.tolist()}")
        return values

    def _speed(self, speed: float) -> float:
        if not 0.0 < float(speed) <= 1.0:
            raise InputError(f"speed {speed!r}: expected a fraction in (0, 1]")
        return max(1e-3, float(speed) * MAX_JOINT_SPEED)

    async def _failure_reason(self) -> str:
        if await self._call(self.receive.isEmergencyStopped):
            return "estop"
        if await self._call(self.receive.isProtectiveStopped):
            return "protective_stop"
        if not await self._call(self.control.isProgramRunning):
            return "control_script_stopped"
        return "refused"

    # ---------------------------------------------------------------- RobotAdapter

    async def state(self) -> RobotState:
        """Reported angles (measured + host offsets), limits, IO, camera description."""
        stamp, q, inputs, outputs = await self._call(self._sample)
        camera: dict[str, Any] = {}
        if self.camera is not None:
            camera_state = await self.camera.state()
            camera = dict(camera_state.camera)
            if isinstance(camera.get("probe"), dict):
                # this driver latches the probe from RTDE samples: at least their spread
                probe = dict(camera["probe"])
                probe["latency_jitter"] = max(float(probe.get("latency_jitter") or 0.0),
                                              self.latch_jitter_s)
                camera["probe"] = probe
        return RobotState(
            q=q + self._offsets,
            zero_offsets=self._offsets.copy(),
            q_min=self.q_min + self._offsets,
            q_max=self.q_max + self._offsets,
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
            },
        )

    async def move_joints(self, q: np.ndarray, speed: float) -> MoveOutcome:
        """moveJ to the reported angles q (6,) rad; the UR gets q - offsets."""
        target = self._check_q(q) - self._offsets
        velocity = self._speed(speed)
        async with self._motion_lock:
            return await self._move_locked(target, velocity)

    async def _move_locked(self, target: np.ndarray, velocity: float) -> MoveOutcome:
        """moveJ to the UR angles target (6,) at velocity rad/s (motion lock held)."""
        ok = await self._call(
            self.control.moveJ, target.tolist(), velocity, JOINT_ACCELERATION, False
        )
        after = float(await self._call(self.receive.getTimestamp))
        if not ok:
            reason = await self._failure_reason()
            measured = await self._fresh_q(after, None)
            return MoveOutcome(completed=False, q=measured + self._offsets, reason=reason)
        measured = await self._fresh_q(after, target)
        return MoveOutcome(completed=True, q=measured + self._offsets)

    async def capture(self, pattern: str = "target", view: int = 0) -> StereoCapture:
        """Stereo pair from the camera service; q at exposure reported (+ host offsets)."""
        if self.camera is None:
            raise ControllerError("UR driver: no camera service configured (--camera HOST:PORT)")
        left, right, q, t = await self.camera.capture(pattern, view)
        if len(q) == 0:  # a camera service without joints (hostpc camera serve): our q, t
            t, q, _, _ = await self._call(self._sample)
        return StereoCapture(left=left, right=right, q=np.asarray(q, float) + self._offsets, t=t)

    async def close(self) -> None:
        """Report the probe latch timing (a warning-level line, so it is always shown),
        stop the control script and disconnect every interface."""
        summary = self.latch_summary()
        if summary is not None:
            logger.warning("%s", summary)
        for name, call in (
            ("stopScript", getattr(self.control, "stopScript", None)),
            ("control.disconnect", getattr(self.control, "disconnect", None)),
            ("io.disconnect", getattr(self.io, "disconnect", None)),
            ("receive.disconnect", getattr(self.receive, "disconnect", None)),
        ):
            if call is None:
                continue
            try:
                await asyncio.to_thread(call)
            except Exception as exc:  # closing must go on
                logger.warning("UR %s: %s failed: %s", self.host, name, exc)
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
    fails, before any ur_rtde interface is constructed.
    """
    import rtde_control
    import rtde_io
    import rtde_receive

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
    token: str | None = None,
    offsets: np.ndarray | list[float] | None = None,
    **_: Any,
) -> UrAdapter:
    """Entry point of `hostpc.robots.connect.open_robot(..., driver="ur")`.

    The UR ports are fixed (30004 / 29999 / 30003), so the `--robot HOST:PORT` port names
    the camera service's zerocal port instead (default 47800). camera: `HOST:PORT`
    overriding that (`none` for no camera). token: the camera service's token (default
    --token / $ZEROCAL_TOKEN / the simulator's).
    """
    from hostpc.robots.connect import resolve_token

    camera_address = parse_camera(camera if camera is not None else (host, port or CAMERA_PORT),
                                  host)
    return await connect_ur(
        host,
        camera_address[0] if camera_address else None,
        camera_address[1] if camera_address else CAMERA_PORT,
        resolve_token(token),
        timeout,
        offsets=offsets,
    )
