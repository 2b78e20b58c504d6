"""`hostpc status`: connect to a controller and print its state.

    hostpc status --robot HOST[:PORT] [--token T] [--json] [--timeout S]

Joints, zero offsets and limits are printed in degrees. The port defaults to 47800
(protocol.DEFAULT_PORT); the token comes from --token, else $ZEROCAL_TOKEN, else the
simulator's default. An unreachable controller raises ConnectionFailed (exit code 3).
"""

from __future__ import annotations

import argparse
import asyncio
import json
import math
from typing import Any

from hostpc.cli.numbers import TIMEOUT_S
from hostpc.errors import InputError
from hostpc.json_object import JsonObject
from hostpc.robots.connect import TOKEN_ENV, parse_robot, resolve_token
from hostpc.transport import ControllerClient, ControllerState
from protocol import DEFAULT_PORT


def register(subparsers: Any) -> None:
    """Add the `status` subcommand."""
    parser = subparsers.add_parser(
        "status",
        help="print a controller's state",
        description="Connect to a controller and print its state (angles in degrees).",
    )
    parser.add_argument(
        "--robot",
        default=f"127.0.0.1:{DEFAULT_PORT}",
        metavar="HOST[:PORT]",
        help=f"controller address (default port {DEFAULT_PORT})",
    )
    parser.add_argument(
        "--token", help=f"shared token (default: ${TOKEN_ENV}, else the simulator's default)"
    )
    parser.add_argument("--json", action="store_true", help="print JSON instead of a table")
    parser.add_argument("--timeout", type=TIMEOUT_S, default=5.0, help="seconds per request")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Entry point of `hostpc status`; returns the exit code."""
    address = parse_robot(args.robot)
    if address.sim:
        raise InputError("--robot sim: status needs a running controller's HOST[:PORT] "
                         "(start one with `controller-stub serve`)")
    host, port = address.host, address.port
    if not args.timeout > 0:
        raise InputError(f"--timeout {args.timeout}: must be positive")
    state = asyncio.run(_fetch(host, port, resolve_token(args.token), args.timeout))
    if args.json:
        print(json.dumps(state_as_dict(state, f"{host}:{port}"), indent=2))
    else:
        print(format_state(state, f"{host}:{port}"))
    return 0


async def _fetch(host: str, port: int, token: str, timeout: float) -> ControllerState:
    async with ControllerClient.connect(host, port, token=token, timeout=timeout) as client:
        return await client.state()


def _degrees(values: Any) -> list[float]:
    return [round(math.degrees(float(v)), 6) for v in values]


def state_as_dict(state: ControllerState, address: str) -> JsonObject:
    """`hostpc status --json`: the state's JSON form, angles in degrees."""
    return {
        "controller": address,
        "kind": "camera_service" if is_camera_service(state) else "controller",
        "robot": state.robot_name,
        "n_joints": state.n_joints,
        "mode": state.mode,
        "time_s": state.time,
        "authenticated": state.authenticated,
        "joints_deg": _degrees(state.q),
        "zero_offsets_deg": _degrees(state.zero_offsets),
        "q_min_deg": _degrees(state.q_min),
        "q_max_deg": _degrees(state.q_max),
        "digital_inputs": list(state.digital_inputs),
        "digital_outputs": list(state.digital_outputs),
        "camera": state.camera,
    }


def _bits(values: tuple[bool, ...]) -> str:
    return " ".join("1" if v else "0" for v in values) or "-"


def is_camera_service(state: ControllerState) -> bool:
    """A camera service (`hostpc camera serve`) speaks the protocol with no robot: no
    robot name and no joints."""
    return state.n_joints == 0 and not state.robot_name


def format_state(state: ControllerState, address: str) -> str:
    """Human-readable table, angles in degrees (a camera service: its camera only)."""
    session = "authenticated" if state.authenticated else "read-only"
    width, height = state.camera.get("image_width"), state.camera.get("image_height")
    if is_camera_service(state):
        camera = f"stereo camera {width}x{height}" if width and height else "stereo camera"
        return (f"camera service {address} (`hostpc camera serve`: no robot, no joints): "
                f"{camera}, time {state.time:.3f} s, session {session}\n"
                f"use it with `hostpc calibrate --driver ur --robot HOST "
                f"--camera-service {address}`")
    lines = [
        f"controller {address}: robot {state.robot_name}, mode {state.mode}, "
        f"time {state.time:.3f} s, session {session}",
        f"{'joint':<6}{'q [deg]':>12}{'offset [deg]':>14}{'min [deg]':>12}{'max [deg]':>12}",
    ]
    columns = zip(state.q, state.zero_offsets, state.q_min, state.q_max, strict=True)
    for i, (q, offset, low, high) in enumerate(columns, start=1):
        lines.append(
            f"{'J' + str(i):<6}{math.degrees(q):>12.4f}{math.degrees(offset):>14.5f}"
            f"{math.degrees(low):>12.2f}{math.degrees(high):>12.2f}"
        )
    lines.append(f"digital inputs : {_bits(state.digital_inputs)}")
    lines.append(f"digital outputs: {_bits(state.digital_outputs)}")
    if width and height:
        lines.append(f"camera: stereo {width}x{height}")
    return "\n".join(lines)
