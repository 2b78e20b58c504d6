"""Open a robot adapter from the command line's `--robot` and `--driver`.

    --robot HOST[:PORT]   a controller at that address (IPv6 as `[::1]:PORT`)
    --robot sim           the simulated controller, started on 127.0.0.1 by the caller
                          (`hostpc.robots.simulator`); this module only recognises the word
    --driver zerocal      our protocol (default; port 47800) | ur (Universal Robots, ur_rtde);
                          the table of drivers is `hostpc.robots.drivers`

`open_robot` returns a connected `RobotAdapter`; an unreachable controller raises
`ConnectionFailed` (CLI exit code 3), a malformed address `InputError` (exit code 2).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

from hostpc.errors import InputError
from hostpc.robots.base import RobotAdapter
from hostpc.robots.drivers import DEFAULT_DRIVER, ConnectOptions, driver_named
from protocol import DEFAULT_PORT
from protocol.auth import read_token_file as auth_token_file

DEFAULT_TOKEN = "zerocal-sim"
"""The simulator's default token (controller_stub scenario: server.token)."""
TOKEN_ENV = "ZEROCAL_TOKEN"


@dataclass(frozen=True)
class RobotAddress:
    """Where the robot is: `sim` (start the simulator) or a host and port."""

    sim: bool
    host: str = ""
    port: int = DEFAULT_PORT

    def __str__(self) -> str:
        if self.sim:
            return "sim"
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"{host}:{self.port}"


def parse_robot(text: str, default_port: int = DEFAULT_PORT) -> RobotAddress:
    """`sim` or `HOST[:PORT]` -> RobotAddress; InputError naming the value if malformed."""
    text = text.strip()
    if text.lower() == "sim":
        return RobotAddress(sim=True)
    host, port_text = text, ""
    if text.startswith("["):
        host, _, rest = text[1:].partition("]")
        port_text = rest[1:] if rest.startswith(":") else rest
    elif text.count(":") == 1:
        host, port_text = text.split(":")
    if not host:
        raise InputError(f"--robot {text!r}: no host (expected HOST[:PORT] or sim)")
    if not port_text and text.endswith(":"):
        raise InputError(f"--robot {text!r}: no port after ':' (expected HOST[:PORT] or sim)")
    if not port_text:
        if text.endswith(":"):
            raise InputError(f"--robot {text!r}: no port after ':' (expected HOST[:PORT])")
        return RobotAddress(sim=False, host=host, port=default_port)
    try:
        port = int(port_text)
    except ValueError:
        raise InputError(f"--robot {text!r}: port {port_text!r} is not a number") from None
    if not 0 < port < 65536:
        raise InputError(f"--robot {text!r}: port {port} out of range 1..65535")
    return RobotAddress(sim=False, host=host, port=port)


def resolve_token(token: str | None) -> str:
    """--token (or the token read from --token-file), else $ZEROCAL_TOKEN, else the
    simulator's default."""
    return token or os.environ.get(TOKEN_ENV) or DEFAULT_TOKEN


TOKEN_ON_COMMAND_LINE_WARNING = (
    "warning: --token is visible to every user of this machine (ps); "
    f"prefer --token-file FILE (mode 0600) or ${TOKEN_ENV}"
)


def read_token_file(path: str | Path) -> str:
    """The token in `path` (its first line, stripped). InputError naming the file if it
    cannot be read, is not a regular file, is readable by group or others (it must be mode
    0600 or stricter), or is empty."""
    try:
        return auth_token_file(Path(path))
    except ValueError as exc:
        raise InputError(str(exc)) from None


async def open_robot(
    address: RobotAddress,
    driver: str = DEFAULT_DRIVER,
    *,
    token: str | None = None,
    timeout: float = 10.0,
    camera: str | None = None,
) -> RobotAdapter:
    """Connect to the robot at `address` with `driver` (a name in the driver table,
    hostpc.robots.drivers); returns an open RobotAdapter. camera: where a driver with a
    camera service fetches captures (`--camera-service`, `none`; None: its default).

    For `sim` the caller starts the simulator first and passes its real address.
    Raises ConnectionFailed (unreachable), InputError (unknown driver, bad address).
    """
    if address.sim:
        raise InputError("--robot sim: start the simulator first (hostpc.robots.simulator)")
    chosen = driver_named(driver)
    return await chosen.connect(address.host, address.port, ConnectOptions(
        token=resolve_token(token), timeout=timeout, camera=camera))
