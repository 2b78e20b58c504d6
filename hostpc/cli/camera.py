"""`hostpc camera`: the stereo camera on this host.

    hostpc camera serve --left SOURCE --right SOURCE [--port 47800] [--host 127.0.0.1]
                        [--token T] [--exposure V] [--gain V] [--max-skew MS]
                        [--describe CELL.json]
        serve the pair over the zerocal protocol (what `--driver ur` fetches captures
        from); runs until Ctrl-C / SIGTERM
    hostpc camera check --left SOURCE --right SOURCE [--frames 20]
        grab pairs and print the timing: frame interval, skew (median, max)

SOURCE: a device index, /dev/videoN, a GStreamer pipeline, a video file or an image
sequence (left_%04d.png); see docs/hardware.md. Exit codes: 0 done, 2 bad input, 3 a camera
does not open or delivers no / frozen frames.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import logging
import signal
import sys
from typing import Any

from hostpc.errors import InputError
from hostpc.sensors.calibrate_options import DEFAULT_MAX_SKEW_MS

DEFAULT_CAMERA_PORT = 47800


def register(subparsers: Any) -> None:
    """Add the `camera` subcommand with `serve` and `check`."""
    parser = subparsers.add_parser("camera", help="serve or check the stereo camera on this host",
                                   description=__doc__.split("\n\n")[0])
    actions = parser.add_subparsers(dest="action", metavar="ACTION", required=True)
    serve = actions.add_parser("serve", help="serve the pair over the zerocal protocol")
    _camera_options(serve)
    serve.add_argument("--host", default="127.0.0.1", help="address to bind (default 127.0.0.1)")
    serve.add_argument("--port", type=int, default=DEFAULT_CAMERA_PORT,
                       help=f"TCP port (default {DEFAULT_CAMERA_PORT}; 0 = any free one)")
    serve.add_argument("--token", help="shared token (default: $ZEROCAL_TOKEN, else the "
                       "simulator's default)")
    serve.add_argument("--describe", metavar="FILE",
                       help="cell JSON reported as the camera description (mount, target, "
                       "chessboard)")
    serve.set_defaults(func=run_serve)
    check = actions.add_parser("check", help="grab pairs and print their timing")
    _camera_options(check)
    check.add_argument("--frames", type=int, default=20, help="pairs to grab (default 20)")
    check.set_defaults(func=run_check)


def _camera_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--left", required=True, metavar="SOURCE", help="left camera")
    parser.add_argument("--right", required=True, metavar="SOURCE", help="right camera")
    parser.add_argument("--exposure", type=float, help="exposure (backend units)")
    parser.add_argument("--gain", type=float, help="gain (backend units)")
    parser.add_argument("--max-skew", type=float, default=DEFAULT_MAX_SKEW_MS, metavar="MS",
                        help="refuse live pairs exposed further apart (default "
                        f"{DEFAULT_MAX_SKEW_MS:g} ms)")
    parser.add_argument("--discard", type=int, metavar="N",
                        help="pairs dropped before each capture (default 1 for live cameras, "
                        "0 for files)")


def _open(args: argparse.Namespace) -> Any:
    from hostpc.sensors.stereo_camera import StereoCamera

    if not args.max_skew > 0:
        raise InputError(f"--max-skew {args.max_skew}: must be positive")
    if args.discard is not None and args.discard < 0:
        raise InputError(f"--discard {args.discard}: must not be negative")
    camera = StereoCamera(args.left, args.right, exposure=args.exposure, gain=args.gain,
                          max_skew_s=args.max_skew * 1e-3, discard=args.discard)
    for name, refused in camera.refused_controls.items():
        print(f"hostpc camera: {name} camera: backend refused {', '.join(refused)}",
              file=sys.stderr)
    return camera


def run_serve(args: argparse.Namespace) -> int:
    """`hostpc camera serve`: returns the exit code (0 after Ctrl-C / SIGTERM)."""
    from hostpc.methods.cell import load_cell_file
    from hostpc.robots.connect import DEFAULT_TOKEN, TOKEN_ENV, resolve_token
    from hostpc.sensors.camera_service import CameraService
    from protocol.auth import is_loopback

    if not 0 <= args.port < 65536:
        raise InputError(f"--port {args.port}: out of range 0..65535")
    token = resolve_token(args.token)
    if token == DEFAULT_TOKEN and not is_loopback(args.host):
        raise InputError(
            f"--host {args.host} is reachable from the network and the token is the public "
            f"default {DEFAULT_TOKEN!r}: anyone there could take pictures through it; give "
            f"another with --token-file FILE (mode 0600) or ${TOKEN_ENV}")
    description = load_cell_file(args.describe) if args.describe else None
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(message)s", stream=sys.stderr)
    from hostpc.serving.log_limits import limit_logging

    limit_logging("asyncio")  # a peer can make it write: one line per record, a few per interval
    with _open(args) as camera:
        service = CameraService(camera, token, description)
        try:
            asyncio.run(_serve(service, args.host, args.port))
        except KeyboardInterrupt:
            pass
    return 0


async def _serve(service: Any, host: str, port: int) -> None:
    try:
        server = await service.start(host, port)
    except OSError as exc:
        raise InputError(f"--host {host} --port {port}: cannot listen ({exc.strerror})") from None
    bound = server.sockets[0].getsockname()
    print(f"serving stereo camera on {bound[0]}:{bound[1]}", flush=True)
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for signum in (signal.SIGINT, signal.SIGTERM):
        try:
            loop.add_signal_handler(signum, stop.set)
        except (NotImplementedError, RuntimeError, ValueError):  # not the main thread
            pass
    async with server:
        await stop.wait()


def run_check(args: argparse.Namespace) -> int:
    """`hostpc camera check`: grab `--frames` pairs, print their timing as JSON lines and a
    summary; exit 3 on a camera failure."""
    import numpy as np

    if args.frames < 2:
        raise InputError(f"--frames {args.frames}: need at least 2")
    timings = []
    with _open(args) as camera:
        for _ in range(args.frames):
            timings.append(camera.capture().timing())
            print(json.dumps(timings[-1]))
    skew_ms = np.abs([t["skew_s"] for t in timings]) * 1e3
    interval_ms = np.diff([t["t_left"] for t in timings]) * 1e3
    print(f"{len(timings)} pairs: skew median {np.median(skew_ms):.3f} ms, max "
          f"{skew_ms.max():.3f} ms; frame interval median {np.median(interval_ms):.1f} ms",
          file=sys.stderr)
    return 0


