"""`hostpc station`: the end-of-line station service (docs/station.md)."""

from __future__ import annotations

import argparse
import asyncio
import logging
import signal
import sys

from hostpc.errors import InputError


def _address(text: str) -> tuple[str, int]:
    host, sep, port = text.rpartition(":")
    if not sep or not host or not port.isdigit() or not 0 <= int(port) <= 65535:
        raise argparse.ArgumentTypeError(f"expected HOST:PORT, got {text!r}")
    return host, int(port)


def register(subparsers: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    parser = subparsers.add_parser(
        "station", help="end-of-line station: a PLC starts calibrations over Modbus TCP",
        description="Serve the station's Modbus register map, run one calibration per PLC "
                    "start command, archive every run, resume an interrupted run on restart.")
    parser.add_argument("--config", required=True, metavar="FILE", help="station config (YAML)")
    parser.add_argument("--db", metavar="URL", help="archive (overrides the config's db)")
    parser.add_argument("--modbus", type=_address, metavar="HOST:PORT",
                        help="Modbus TCP address (overrides the config; default 127.0.0.1:5020)")
    parser.add_argument("--http", type=_address, metavar="HOST:PORT",
                        help="serve the live page (read-only) here, e.g. 127.0.0.1:8080")
    parser.set_defaults(func=run)


async def _serve(args: argparse.Namespace) -> int:
    from hostpc.station.checks import check_station_config
    from hostpc.station.config import load_station_config
    from hostpc.station.service import Station
    from hostpc.station.web import serve_page

    config = load_station_config(args.config, db=args.db, modbus=args.modbus)
    # the whole configuration, before anything listens or runs (docs/station.md)
    await asyncio.to_thread(check_station_config, config, args.config)
    station = Station(config, args.config)
    page = None
    http = args.http or config.http_address()
    if http:  # the ports first (`http`, then `modbus`), then the archive: nothing created
        try:  # by a station that refuses to start
            page = await serve_page(station, *http)
            http = page.address
        except OSError as exc:
            key = "--http" if args.http else f"{args.config}: http:"
            raise InputError(f"{key} {http[0]}:{http[1]}: cannot listen "
                             f"({exc.strerror})") from None
    try:
        await station.open()  # the PLC's port (`modbus`), the archive (`db`), `runs_dir`
    except BaseException:
        if page is not None:
            await page.cleanup()
        raise
    loop = asyncio.get_running_loop()
    for signum in (signal.SIGTERM, signal.SIGINT):
        loop.add_signal_handler(signum, station.stop)
    task = asyncio.create_task(station.run())
    assert station.modbus_address is not None
    host, port = station.modbus_address
    print(f"hostpc station {config.station}: PLC registers on {host}:{port}"
          + (f", page on http://{http[0]}:{http[1]}/" if http else "")
          + f", archive {config.database_url()}", flush=True)
    try:
        await task
    finally:
        if page is not None:
            await page.cleanup()
    print(f"hostpc station {config.station}: stopped", flush=True)
    return 0


def run(args: argparse.Namespace) -> int:
    from hostpc.serving.log_limits import SERVER_LOGGERS, limit_logging

    logging.basicConfig(level=logging.INFO, stream=sys.stderr,
                        format="%(asctime)s %(name)s %(levelname)s %(message)s")
    # a peer can make these write: one line per record, a few per interval (security.md)
    limit_logging(*SERVER_LOGGERS, "hostpc.station")
    try:
        return asyncio.run(_serve(args))
    except OSError as exc:
        raise InputError(f"cannot start the station: {exc.strerror or exc}") from None
