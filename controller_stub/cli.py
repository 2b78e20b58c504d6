"""`controller-stub` command line: run the simulated controller.

    controller-stub serve [--scenario FILE] [--host 127.0.0.1] [--port 47800]
                          [--truth-out FILE] [--modbus-port PORT] [--ur] [--log-level LEVEL]
                          [--token-file FILE] [--modbus-writable]
                          [--sensor-plugin FOLDER ...]

`serve` prints exactly `listening on HOST:PORT` (flushed) once it accepts connections; with
`--port 0` the OS picks a free port and that line tells which. With `--modbus-port` the
digital IO is also served over Modbus TCP (0, the default, means no Modbus server); the
line `modbus on HOST:PORT` is printed before `listening on`. With `--ur` the same simulated
robot is also served as a Universal Robots controller (RTDE 30004, dashboard 29999, script
port 30003 on --host; fixed ports, see docs/robots.md) and the line
`ur on HOST (rtde 30004, dashboard 29999, script 30003)` is printed before `listening on`.
`--sensor-plugin FOLDER` (repeatable) loads the simulated sensors of a measurement kind's
folder (`FOLDER/sim_sensor.py`, controller_stub/sensors/registry.py), read through
`sensor_read`; a sensor module that imports hostpc is refused (exit 2): the simulator keeps
its own models. Errors are one line on stderr.

The token: `--token-file FILE` (a file readable by its owner only, mode 0600; its first
line), else `$ZEROCAL_TOKEN`, else the scenario's `server.token`. `--token TOKEN` still works
but warns: a command line is visible to every user of the machine (`ps`). An empty token is
refused (exit 2), and so is binding a non-loopback `--host` while the token is still the
public default (`zerocal-sim`): anyone on the network could move the robot. The Modbus
server is read-only unless `--modbus-writable` (or
`server.modbus_writable: true` in the scenario): Modbus has no authentication at all.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import gc
import logging
import os
import signal
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from protocol import DEFAULT_PORT
from protocol.auth import is_loopback, read_token_file

if TYPE_CHECKING:
    from controller_stub.network.modbus_io import ModbusIoServer


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="controller-stub", description="zerocal simulated robot controller"
    )
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND")
    serve = subparsers.add_parser("serve", help="serve a scenario over the zerocal protocol")
    serve.add_argument(
        "--scenario",
        type=Path,
        help="scenario file (YAML/JSON); default: the packaged default.yaml",
    )
    serve.add_argument("--host", default="127.0.0.1", help="address to bind (default 127.0.0.1)")
    serve.add_argument(
        "--port", type=int, default=DEFAULT_PORT, help=f"TCP port, 0 = any (default {DEFAULT_PORT})"
    )
    serve.add_argument("--truth-out", type=Path, help="write the hidden truth here as JSON")
    serve.add_argument(
        "--modbus-port", type=int, default=0, help="Modbus TCP port for the IO (default 0 = off)"
    )
    serve.add_argument(
        "--modbus-writable",
        action="store_true",
        help="let Modbus clients write the digital outputs (default: read-only)",
    )
    serve.add_argument(
        "--token-file",
        type=Path,
        help="file holding the shared token (mode 0600; default: $ZEROCAL_TOKEN, else the "
        "scenario's server.token)",
    )
    serve.add_argument(
        "--token", help="shared token (discouraged: visible in the process list; warns)"
    )
    serve.add_argument(
        "--ur",
        action="store_true",
        help="also serve the robot as a Universal Robots controller (RTDE 30004, dashboard "
        "29999, script 30003) for ur_rtde",
    )
    serve.add_argument(
        "--sensor-plugin",
        type=Path,
        action="append",
        default=[],
        metavar="FOLDER",
        help="a measurement kind's folder whose sim_sensor.py simulates its instrument "
        "(repeatable)",
    )
    serve.add_argument(
        "--check",
        action="store_true",
        help="load and check the scenario (and sensor plugins) as serving would, print "
        "'scenario checked' and exit without listening (2: refused)",
    )
    serve.add_argument("--log-level", default="WARNING", help="Python logging level")
    return parser


def _load_scenario(path: Path | None) -> object:
    from controller_stub.scenario.spec import default_scenario, load_scenario

    return load_scenario(path) if path is not None else default_scenario()


async def _serve(args: argparse.Namespace) -> int:
    from controller_stub.network.server import ControllerServer

    scenario: Any = _load_scenario(args.scenario)
    try:
        token = _resolve_token(args, scenario)
    except ValueError as exc:
        print(f"controller-stub serve: error: {exc}", file=sys.stderr)
        return 2
    refusal = _exposure_refusal(args.host, token, scenario)
    if refusal is not None:
        print(f"controller-stub serve: error: {refusal}", file=sys.stderr)
        return 2
    from controller_stub.sensors.registry import SensorPluginError

    try:
        server = ControllerServer.from_scenario(scenario, truth_out=args.truth_out,
                                                sensor_folders=args.sensor_plugin)
    except SensorPluginError as exc:
        print(f"controller-stub serve: error: {exc}", file=sys.stderr)
        return 2
    if "hostpc" in sys.modules:  # a simulated sensor pulled the fitter's code in
        print("controller-stub serve: error: a simulated sensor (--sensor-plugin or entry "
              "point) imports hostpc; it may use numpy and controller_stub only (the simulator "
              "keeps its own models)", file=sys.stderr)
        return 2
    if args.check:
        print("scenario checked", flush=True)
        return 0
    server.token = token
    modbus: ModbusIoServer | None = None
    ur: Any = None
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for signum in (signal.SIGINT, signal.SIGTERM):
        with contextlib.suppress(NotImplementedError, RuntimeError):
            loop.add_signal_handler(signum, stop.set)
    try:
        if args.modbus_port:
            # pymodbus only when asked for: its import is ~0.2 s of every stub's start-up
            from controller_stub.network.modbus_io import ModbusIoServer

            modbus = ModbusIoServer(
                server.sim,
                host=args.host,
                port=args.modbus_port,
                writable=args.modbus_writable or scenario.server.modbus_writable,
            )
            host, port = await modbus.start()
            print(f"modbus on {host}:{port}", flush=True)
        if args.ur:
            from controller_stub.ur import UrPersonality

            try:
                ur = UrPersonality(server.sim, server)
            except ValueError as exc:
                print(f"controller-stub serve: error: --ur: {exc}", file=sys.stderr)
                return 2
            ports = await ur.start(args.host)
            print(
                f"ur on {args.host} (rtde {ports['rtde'][1]}, dashboard {ports['dashboard'][1]}, "
                f"script {ports['script'][1]})",
                flush=True,
            )
        host, port = await server.start(args.host, args.port)
        print(f"listening on {host}:{port}", flush=True)
        await stop.wait()
    finally:
        if ur is not None:
            await ur.close()
        await server.close()
        if modbus is not None:
            await modbus.close()
    return 0


TOKEN_ENV = "ZEROCAL_TOKEN"


def _resolve_token(args: argparse.Namespace, scenario: Any) -> str:
    """--token, else --token-file, else $ZEROCAL_TOKEN, else the scenario's; ValueError
    (one line) for an empty token or a token file others can read."""
    if args.token is not None and args.token.strip():
        print(
            "controller-stub serve: warning: --token is visible to every user of this machine "
            f"(ps); prefer --token-file or ${TOKEN_ENV}",
            file=sys.stderr,
        )
        token: str = args.token
        source = "--token"
    elif args.token is not None:
        token, source = args.token, "--token"
    elif args.token_file is not None:
        token, source = read_token_file(args.token_file), f"--token-file {args.token_file}"
    elif os.environ.get(TOKEN_ENV) is not None:
        token, source = os.environ[TOKEN_ENV], f"${TOKEN_ENV}"
    else:
        token, source = scenario.server.token, "server.token"
    if not token.strip():
        raise ValueError(f"{source}: the token is empty")
    return token


def _exposure_refusal(host: str, token: str, scenario: Any) -> str | None:
    """Why serving on `host` with `token` is refused, or None: a non-loopback address with
    the public default token would let anyone on the network move the robot."""
    default_token = type(scenario.server).model_fields["token"].default
    if token != default_token or is_loopback(host):
        return None
    return (
        f"--host {host} is reachable from the network and the token is the public default "
        f"{default_token!r}; give another with --token-file (or ${TOKEN_ENV}, or server.token "
        "in the scenario)"
    )


def main(argv: list[str] | None = None) -> int:
    """`controller-stub ARGV` (None: the process's command line, which ends with it: its
    last garbage collections are spared, `exit_without_collecting`)."""
    try:
        return _main(argv)
    finally:
        if argv is None:
            exit_without_collecting()


def exit_without_collecting() -> None:
    """Leave every object that exists now out of the interpreter's last garbage collections
    (`gc.freeze`): they visit every object of the simulator's modules, ~0.2 s between
    SIGTERM and the end of the process that hostpc waits for. atexit handlers and the
    flushing of the standard streams run as ever; the stub's files are written (atomically)
    while it runs."""
    gc.freeze()


def _main(argv: list[str] | None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.command != "serve":
        parser.print_help()
        return 2
    logging.basicConfig(
        level=getattr(logging, str(args.log_level).upper(), logging.WARNING),
        format="%(asctime)s %(levelname)s %(name)s: %(message)s",
        stream=sys.stderr,
    )
    try:
        from controller_stub.scenario.spec import ScenarioError

        try:
            return asyncio.run(_serve(args))
        except ScenarioError as exc:
            print(f"controller-stub serve: error: {exc}", file=sys.stderr)
            return 2
    except OSError as exc:
        print(f"controller-stub serve: error: cannot listen: {exc}", file=sys.stderr)
        return 3
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())
