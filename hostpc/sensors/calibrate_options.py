"""The `hostpc calibrate` options of the host sensors, and where the run's robot comes from.

    --camera-left SOURCE --camera-right SOURCE   cameras on the host (sources.py) instead of
                                                 the controller's captures
    --camera-service HOST:PORT                   --driver ur: where `hostpc camera serve`
                                                 runs (default: the robot's host, 47800)
    --exposure VALUE --gain VALUE                set where the backend allows
    --max-skew MS                                refuse a live pair whose skew exceeds MS
    --discard N                                  pairs dropped before each capture
    --record [DIR]                               keep every call, image pair, joint reading
                                                 and timestamp (default DIR: RUN/recording)
    --replay DIR                                 run again from a recording, without a robot

`open_with_sensors` is the one call `hostpc.cli.calibrate` makes instead of opening the
robot itself; `replay_inputs` gives a replay the settings the recorded run was asked for.
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Awaitable, Callable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

from hostpc.errors import InputError
from hostpc.robots.base import RobotAdapter
from hostpc.robots.drivers import DEFAULT_DRIVER, DRIVERS, driver_named

if TYPE_CHECKING:
    from hostpc.calibrate.run_values import RobotInfo

RECORDING_FOLDER = "recording"
DEFAULT_MAX_SKEW_MS = 20.0


def add_sensor_options(parser: argparse.ArgumentParser) -> None:
    """Add the options of the module docstring to `hostpc calibrate`."""
    group = parser.add_argument_group("host cameras, record and replay (docs/hardware.md)")
    group.add_argument("--camera-left", metavar="SOURCE",
                       help="left camera on this host: device index, /dev/videoN, GStreamer "
                       "pipeline, video file or image sequence (left_%%04d.png)")
    group.add_argument("--camera-right", metavar="SOURCE", help="right camera (as --camera-left)")
    group.add_argument("--camera-service", metavar="HOST:PORT",
                       help="with --driver ur: the camera service (`hostpc camera serve`) to "
                       "fetch captures from (default: the robot's host, port 47800)")
    group.add_argument("--exposure", type=float, metavar="VALUE",
                       help="camera exposure in backend units (V4L2: 100 us steps)")
    group.add_argument("--gain", type=float, metavar="VALUE", help="camera gain (backend units)")
    group.add_argument("--max-skew", type=float, default=DEFAULT_MAX_SKEW_MS, metavar="MS",
                       help="refuse a pair of live cameras exposed further apart than this "
                       f"(default {DEFAULT_MAX_SKEW_MS:g} ms)")
    group.add_argument("--discard", type=int, metavar="N",
                       help="pairs grabbed and dropped before each capture (default 1 for "
                       "live cameras: no frame from before the robot stopped; 0 for files)")
    group.add_argument("--record", nargs="?", const="", default=None, metavar="DIR",
                       help="record every image pair with its joint readings and timestamps "
                       f"(default DIR: RUN/{RECORDING_FOLDER})")
    group.add_argument("--replay", metavar="DIR",
                       help="run the whole pipeline again from a recording, without a robot")


def check_sensor_options(args: argparse.Namespace) -> None:
    """One line (exit code 2) for combinations that make no sense."""
    left, right = getattr(args, "camera_left", None), getattr(args, "camera_right", None)
    if bool(left) != bool(right):
        raise InputError("--camera-left and --camera-right go together (a stereo pair)")
    if getattr(args, "replay", None):
        if args.robot or args.resume or left:
            raise InputError("--replay DIR runs without a robot or cameras: drop --robot, "
                             "--resume and --camera-*")
    if getattr(args, "record", None) is not None and args.resume:
        raise InputError("--record is for a new run, not a --resume")
    if getattr(args, "camera_service", None) and (
            left or not driver_named(getattr(args, "driver", DEFAULT_DRIVER)).camera_service):
        with_service = " / ".join(d.name for d in DRIVERS.values() if d.camera_service)
        raise InputError(f"--camera-service is for --driver {with_service} without "
                         "--camera-left/right")
    if getattr(args, "discard", None) is not None and args.discard < 0:
        raise InputError(f"--discard {args.discard}: must not be negative")
    max_skew = getattr(args, "max_skew", DEFAULT_MAX_SKEW_MS)
    if not max_skew > 0:
        raise InputError(f"--max-skew {max_skew}: must be positive")


REPLAY_FIXED = frozenset({
    "method", "poses", "verify_poses", "seed", "known", "cell", "rig", "depth", "pixel_floor",
    "probe_io", "modbus", "push", "force", "max_correction", "verify_alpha",
    "verify_tolerance", "verify_factor", "speed", "criterion", "target_sigma", "candidates",
    "scenario", "effects", "plugin", "loss", "cv_folds", "prior", "hold"})
"""Options a replay may not be given: it plans, measures, fits and pushes exactly as the
recorded run did (its settings come from the recording)."""


def check_replay_options(args: argparse.Namespace,
                         defaults: Mapping[str, tuple[str, Any]]) -> None:
    """One line (exit code 2) if a --replay is given an option that would change the
    recorded run. defaults: option dest -> (its flag, its parser default)."""
    given = [flag for dest, (flag, default) in defaults.items()
             if dest in REPLAY_FIXED and getattr(args, dest, default) != default]
    if given:
        raise InputError(f"--replay runs exactly as recorded (its settings come from the "
                         f"recording): drop {', '.join(given)}")


def replay_inputs(args: argparse.Namespace, default_out: Callable[[str], Path]
                  ) -> tuple[Any, str, Any, Any, tuple[str, ...] | None, Path]:
    """For `--replay DIR`: (address, driver, settings, cell_file, known, run_dir) of the
    recorded run (known resolved as the recorded run resolved it)."""
    from hostpc.robots.connect import RobotAddress
    from hostpc.sensors.recording import TAPE_FILE, read_header

    folder = Path(args.replay)
    header = read_header(folder)
    settings, cell_file, known = header.settings, header.cell_file, header.known
    if settings is None:
        raise InputError(f"--replay {folder}: the recording holds no settings")
    default_known = header.default_known
    if known is None and default_known:
        listed = (cell_file or {}).get("known")
        if listed is None:
            with (folder / TAPE_FILE).open(encoding="utf-8") as tape:
                first = json.loads(tape.readline() or "{}")
            listed = ((first.get("result") or {}).get("camera") or {}).get("known")
        known = None if isinstance(listed, list) else default_known
    run_dir = Path(args.out) if args.out else default_out(settings.method)
    if (run_dir / "journal.jsonl").exists():
        raise InputError(f"--out {run_dir}: already holds a run; choose another folder")
    address = RobotAddress(sim=False, host=f"replay:{folder}", port=0)
    return address, "replay", settings, cell_file, None if known is None else tuple(known), \
        run_dir


def robot_camera(args: argparse.Namespace, driver: str) -> str | None:
    """Where a driver with a camera service (the UR driver) gets its captures: `none` with
    host cameras, --camera-service, else None (its default)."""
    if not driver_named(driver).camera_service:
        return None
    if getattr(args, "camera_left", None):
        return "none"
    service = getattr(args, "camera_service", None)
    return str(service) if service else None


async def open_with_sensors(args: argparse.Namespace, run_dir: Path, settings: Any,
                            cell_file: Any, known: tuple[str, ...] | None,
                            default_known: tuple[str, ...], robot_info: RobotInfo,
                            open_robot: Callable[[], Awaitable[RobotAdapter]]) -> RobotAdapter:
    """The run's robot: the recording (--replay), else `open_robot()` with the host cameras
    (--camera-left/right) and the recorder (--record) around it."""
    check_sensor_options(args)
    if any(getattr(args, name, None) is not None for name in ("replay", "record", "camera_left")):
        _deterministic_opencv()
    if getattr(args, "replay", None):
        from hostpc.sensors.recording import ReplayAdapter

        return ReplayAdapter(Path(args.replay))
    camera = None
    if getattr(args, "camera_left", None):
        from hostpc.sensors.stereo_camera import StereoCamera

        camera = StereoCamera(args.camera_left, args.camera_right, exposure=args.exposure,
                              gain=args.gain, max_skew_s=args.max_skew * 1e-3,
                              discard=args.discard)
    try:
        robot = await open_robot()
    except BaseException:
        if camera is not None:
            camera.close()
        raise
    if camera is not None:
        from hostpc.sensors.host_cameras import TIMING_FILE, HostCameraAdapter

        run_dir.mkdir(parents=True, exist_ok=True)
        robot = HostCameraAdapter(robot, camera, run_dir / TIMING_FILE)
    if getattr(args, "record", None) is not None:
        from hostpc.sensors.recording import RecordingAdapter, RecordingHeader

        folder = Path(args.record) if args.record else run_dir / RECORDING_FOLDER
        header = RecordingHeader(
            settings=settings, cell_file=cell_file, known=known, default_known=default_known,
            robot=robot_info,
            cameras=None if camera is None else tuple(s.text for s in camera.sources))
        try:
            robot = RecordingAdapter(robot, folder, header)
        except BaseException:
            await robot.close()
            raise
    return robot


def _deterministic_opencv() -> None:
    """One OpenCV worker thread: its stereo calibration sums in thread order, so with
    several threads the same images give a rig that differs in the 12th digit, and a replay
    would plan other poses (measured: K_left[0, 0] varied 1399.86717033479..67 over three
    runs on the same 20 views with 2 threads, identical with 1)."""
    import cv2

    cv2.setNumThreads(1)
