"""RobotAdapter for Universal Robots through the ur_rtde library (`--driver ur`).

    RTDEReceiveInterface   joint angles (getActualQ), digital IO bits, timestamps
    RTDEControlInterface   moveJ / stopJ (ur_rtde uploads its control script to 30003)
    RTDEIOInterface        standard digital outputs
    ControllerClient       stereo captures from the camera service (zerocal protocol,
                           `--camera HOST:PORT`, default the robot's host, port 47800)

Two hazards of ur_rtde shape this module (both measured):
1. Its constructors hold the Python GIL while they wait for the controller, so a peer that
   accepts a TCP connection and never answers freezes the whole interpreter, event loop
   included. `connect_ur` therefore first talks to the controller with plain asyncio under
   a timeout: an RTDE protocol-version request and controller-version request on 30004, the
   dashboard greeting and queries on 29999, a TCP connect to 30003. Only a controller that
   answered all three gets a ur_rtde interface. Every ur_rtde call runs in a worker thread
   (`asyncio.to_thread`), never on the event loop.
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
reports true angles. The offsets live in this adapter (and in the files
`hostpc.robots.ur_export` writes for ROS / URScript users); the robot itself is unchanged,
and other software driving it must load the exported files to benefit.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import struct
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from hostpc.errors import ConnectionFailed, ControllerError, InputError, RequestTimeout
from hostpc.robots.base import ContactOutcome, MoveOutcome, RobotState, StereoCapture

logger = logging.getLogger(__name__)

RTDE_PORT = 30004
DASHBOARD_PORT = 29999
SCRIPT_PORT = 30003
CAMERA_PORT = 47800
RTDE_PROTOCOL_VERSION = 2
MAX_JOINT_SPEED = 3.14
"""rad/s; ur_rtde's UR_JOINT_VELOCITY_MAX, `speed` 1.0 maps to it."""
JOINT_ACCELERATION = 1.4
"""rad/s^2, UR's default movej acceleration."""
SETTLE_TOLERANCE_RAD = 1e-3
SETTLE_TIMEOUT_S = 2.0
MAX_OFFSET_RAD = math.radians(5.0)
"""Largest host zero offset accepted by set_offsets (a bigger one is a fitting error)."""
N_DIGITAL_IO = 16
"""Standard (0-7) and configurable (8-15) digital IO, bit i of the RTDE IO bit words."""

T = TypeVar("T")


@dataclass(frozen=True)
class UrControllerInfo:
    """What the asyncio pre-check learned: versions, model, serial, remote control."""

    controller_version: tuple[int, int, int, int]
    polyscope: str
    robot_model: str
    serial_number: str
    remote_control: bool | None

    @property
    def robot_name(self) -> str:
        """zerocal robot name (`ur5e`, `ur10e`, ... for e-Series, `ur5`, ... for CB3)."""
        model = self.robot_model.strip().lower()
        if not model.startswith("ur"):
            return model or "ur"
        if self.controller_version[0] >= 5 and model[-1].isdigit() and model not in (
            "ur20", "ur30", "ur8long", "ur15", "ur18"
        ):
            return model + "e"
        return model


# ---------------------------------------------------------------------- asyncio pre-checks


def _package(kind: str, payload: bytes = b"") -> bytes:
    return struct.pack(">HB", 3 + len(payload), ord(kind)) + payload


async def _read_package(reader: asyncio.StreamReader) -> tuple[int, bytes]:
    size, kind = struct.unpack(">HB", await reader.readexactly(3))
    if size < 3:
        raise ValueError(f"RTDE package size {size} < 3")
    return kind, await reader.readexactly(size - 3)


async def _open(host: str, port: int, timeout: float, what: str) -> tuple[
    asyncio.StreamReader, asyncio.StreamWriter
]:
    try:
        return await asyncio.wait_for(asyncio.open_connection(host, port), timeout)
    except TimeoutError as exc:
        raise ConnectionFailed(
            f"UR {what} {host}:{port}: no connection within {timeout:.1f} s"
        ) from exc
    except OSError as exc:
        raise ConnectionFailed(f"UR {what} {host}:{port}: cannot connect: {exc}") from exc


async def _close(writer: asyncio.StreamWriter) -> None:
    writer.close()
    with contextlib.suppress(Exception):
        await writer.wait_closed()


async def probe_rtde(
    host: str, port: int = RTDE_PORT, timeout: float = 3.0
) -> tuple[int, int, int, int]:
    """Check that `host:port` speaks RTDE: protocol version 2, then the controller version.

    Pure asyncio with a timeout, so a peer that accepts and stays silent cannot freeze the
    interpreter (ur_rtde's constructors would). Returns (major, minor, bugfix, build).
    Raises ConnectionFailed with the reason.
    """
    reader, writer = await _open(host, port, timeout, "RTDE")
    try:
        async with asyncio.timeout(timeout):
            writer.write(_package("V", struct.pack(">H", RTDE_PROTOCOL_VERSION)))
            await writer.drain()
            kind, body = await _read_package(reader)
            if kind != ord("V") or not body or not body[0]:
                raise ConnectionFailed(
                    f"UR RTDE {host}:{port}: the controller refused RTDE protocol version "
                    f"{RTDE_PROTOCOL_VERSION} (reply type {kind}, {body[:4]!r})"
                )
            writer.write(_package("v"))
            await writer.drain()
            kind, body = await _read_package(reader)
            if kind != ord("v") or len(body) < 16:
                raise ConnectionFailed(
                    f"UR RTDE {host}:{port}: bad controller-version reply (type {kind})"
                )
            major, minor, bugfix, build = struct.unpack(">4I", body[:16])
            return major, minor, bugfix, build
    except TimeoutError as exc:
        raise ConnectionFailed(
            f"UR RTDE {host}:{port}: the peer accepted the connection but did not answer the "
            f"RTDE protocol-version request within {timeout:.1f} s (is it a UR controller with "
            "RTDE enabled?); no ur_rtde interface was created"
        ) from exc
    except (asyncio.IncompleteReadError, ConnectionError, ValueError) as exc:
        raise ConnectionFailed(f"UR RTDE {host}:{port}: connection broken: {exc}") from exc
    finally:
        await _close(writer)


async def probe_dashboard(
    host: str, port: int = DASHBOARD_PORT, timeout: float = 3.0
) -> tuple[str, str, str, bool | None]:
    """Greeting and (PolyScope version, robot model, serial number, in remote control) from
    the dashboard server, in asyncio under `timeout`. ConnectionFailed if it does not answer.
    """
    reader, writer = await _open(host, port, timeout, "dashboard")

    async def ask(command: str) -> str:
        writer.write(f"{command}\n".encode())
        await writer.drain()
        return (await reader.readline()).decode(errors="replace").strip()

    try:
        async with asyncio.timeout(timeout):
            greeting = (await reader.readline()).decode(errors="replace").strip()
            if "dashboard" not in greeting.lower():
                raise ConnectionFailed(
                    f"UR dashboard {host}:{port}: unexpected greeting {greeting!r}"
                )
            polyscope = await ask("PolyscopeVersion")
            model = await ask("get robot model")
            serial = await ask("get serial number")
            remote_text = (await ask("is in remote control")).lower()
    except TimeoutError as exc:
        raise ConnectionFailed(
            f"UR dashboard {host}:{port}: no answer within {timeout:.1f} s"
        ) from exc
    except (asyncio.IncompleteReadError, ConnectionError) as exc:
        raise ConnectionFailed(f"UR dashboard {host}:{port}: connection broken: {exc}") from exc
    finally:
        await _close(writer)
    remote = True if "true" in remote_text else False if "false" in remote_text else None
    if model.lower().startswith("could not understand"):
        model = ""
    if not serial.isdigit():
        serial = ""
    return polyscope, model, serial, remote


async def probe_port(host: str, port: int, timeout: float, what: str) -> None:
    """TCP connect to `host:port` under `timeout`; ConnectionFailed otherwise."""
    _, writer = await _open(host, port, timeout, what)
    await _close(writer)


async def check_controller(host: str, timeout: float = 3.0) -> UrControllerInfo:
    """All asyncio pre-checks of a UR controller (RTDE, dashboard, script port)."""
    version = await probe_rtde(host, RTDE_PORT, timeout)
    polyscope, model, serial, remote = await probe_dashboard(host, DASHBOARD_PORT, timeout)
    await probe_port(host, SCRIPT_PORT, timeout, "script port")
    if remote is False:
        raise ConnectionFailed(
            f"UR {host}: the robot is in local control; switch it to remote control on the "
            "teach pendant (docs/robots.md)"
        )
    return UrControllerInfo(version, polyscope, model, serial, remote)


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
        """(timestamp, actual q (6,), input bits, output bits) from the receive interface."""
        return (
            float(self.receive.getTimestamp()),
            np.asarray(self.receive.getActualQ(), float),
            int(self.receive.getActualDigitalInputBits()),
            int(self.receive.getActualDigitalOutputBits()),
        )

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

    def _check_offsets(self, offsets: np.ndarray | list[float]) -> np.ndarray:
        values = self._check_q(offsets, "offsets")
        if np.any(np.abs(values) > MAX_OFFSET_RAD):
            i = int(np.argmax(np.abs(values)))
            raise ControllerError(
                f"UR host offsets: joint {i + 1} offset {math.degrees(values[i]):.3f} deg "
                f"exceeds the limit {math.degrees(MAX_OFFSET_RAD):.1f} deg"
            )
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

    async def guarded_move(self, q: np.ndarray, speed: float, io_line: int) -> ContactOutcome:
        """Asynchronous moveJ toward q (6,) polling digital input `io_line` over RTDE; on a
        rising edge the angles of that sample are latched and the robot stopped (stopJ).

        The latch is only as good as the RTDE sample period (2 ms at 500 Hz) plus the
        detection delay; prefer a controller-side latch where precision matters.
        """
        if not 0 <= int(io_line) < N_DIGITAL_IO:
            raise InputError(f"io_line {io_line}: expected 0..{N_DIGITAL_IO - 1}")
        target = self._check_q(q) - self._offsets
        velocity = self._speed(speed)
        async with self._motion_lock:
            _, _, inputs, _ = await self._call(self._sample)
            previous = bool(inputs >> io_line & 1)
            status0 = await self._call(self.control.getAsyncOperationProgressEx)
            ok = await self._call(
                self.control.moveJ, target.tolist(), velocity, JOINT_ACCELERATION, True
            )
            if not ok:
                reason = await self._failure_reason()
                _, q_now, _, _ = await self._call(self._sample)
                return ContactOutcome(False, None, q_now + self._offsets, reason=reason)
            op_id = None
            loop = asyncio.get_running_loop()
            deadline = loop.time() + max(self.timeout, 60.0)
            while True:
                stamp, q_now, inputs, _ = await self._call(self._sample)
                level = bool(inputs >> io_line & 1)
                if level and not previous:
                    await self._call(self.control.stopJ, 2.0, False)
                    measured = await self._fresh_q(stamp, None)
                    return ContactOutcome(
                        True, q_now + self._offsets, measured + self._offsets
                    )
                previous = level
                status = await self._call(self.control.getAsyncOperationProgressEx)
                if op_id is None and status.operationId() != status0.operationId():
                    op_id = status.operationId()
                if op_id is not None and not status.isAsyncOperationRunning():
                    measured = await self._fresh_q(stamp, target)
                    return ContactOutcome(
                        False, None, measured + self._offsets, reason="no_contact"
                    )
                if loop.time() > deadline:
                    await self._call(self.control.stopJ, 2.0, False)
                    raise RequestTimeout(f"UR {self.host}: guarded move did not end")
                await asyncio.sleep(0.001)

    async def capture(self, pattern: str = "target", view: int = 0) -> StereoCapture:
        """Stereo pair from the camera service; q at exposure reported (+ host offsets)."""
        if self.camera is None:
            raise ControllerError("UR driver: no camera service configured (--camera HOST:PORT)")
        left, right, q, t = await self.camera.capture(pattern, view)
        if len(q) == 0:  # a camera service without joints (hostpc camera serve): our q, t
            t, q, _, _ = await self._call(self._sample)
        return StereoCapture(left=left, right=right, q=np.asarray(q, float) + self._offsets, t=t)

    async def get_offsets(self) -> np.ndarray:
        """The host zero offsets (6,) rad (the UR's own calibration is not readable)."""
        return self._offsets.copy()

    async def set_offsets(self, offsets: np.ndarray) -> tuple[np.ndarray, str]:
        """Replace the host zero offsets (nothing is written to the robot); returns
        (previous offsets, rollback id)."""
        new = self._check_offsets(offsets)
        previous = self._offsets.copy()
        self._rollback_counter += 1
        rollback_id = f"ur-host-{self._rollback_counter}"
        self._rollbacks[rollback_id] = previous
        self._offsets = new
        logger.info("UR %s: host zero offsets set to %s (robot unchanged)", self.host, new)
        return previous, rollback_id

    def export_offsets(self, directory: str | Path, robot: str,
                       offsets: np.ndarray) -> dict[str, Path]:
        """Write `offsets` (6,) rad of robot model `robot` (e.g. `ur5e`) into `directory` as
        the ur_description calibration yaml, URDF joints and URScript snippet
        (`hostpc.robots.ur_export`); returns {"yaml"|"urdf"|"urscript": path}."""
        from hostpc.kinematics import get_robot
        from hostpc.robots.ur_export import write_exports

        return write_exports(directory, get_robot(robot), self._check_offsets(offsets),
                             stem=self.EXPORT_STEM)

    async def rollback(self, rollback_id: str) -> np.ndarray:
        """Restore the offsets saved under `rollback_id`; returns the replaced ones."""
        try:
            saved = self._rollbacks[rollback_id]
        except KeyError:
            raise ControllerError(f"UR host offsets: unknown rollback id {rollback_id!r}") from None
        replaced = self._offsets.copy()
        self._offsets = saved.copy()
        return replaced

    async def close(self) -> None:
        """Stop the control script and disconnect every interface."""
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
        receive = await asyncio.to_thread(rtde_receive.RTDEReceiveInterface, host)
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
