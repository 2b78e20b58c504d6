"""The robot drivers `--driver` chooses from: one table, as `hostpc.methods` has for methods.

    zerocal   our protocol (`hostpc.robots.zerocal`): the simulated controller or any
              controller speaking it; the controller keeps the zero offsets and rollback ids
    ur        Universal Robots through ur_rtde (`hostpc.robots.ur`): offsets applied on the
              host and exported as files, captures from a camera service

A driver is looked up here and nowhere else: `open_robot` (connect.py) connects with it,
`hostpc rollback` asks whether its offsets can be rolled back, the sensor options whether it
fetches captures from a camera service. A new driver is a module with a `RobotAdapter` and
one row below. What an adapter offers beyond `RobotAdapter` is its `capabilities`
(hostpc.robots.base), not a column here.
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable
from dataclasses import dataclass

from hostpc.errors import InputError
from hostpc.robots import ur
from hostpc.robots.base import RobotAdapter
from hostpc.robots.zerocal import ZerocalAdapter


@dataclass(frozen=True)
class ConnectOptions:
    """What `open_robot` passes every driver: token (already resolved: --token, the token
    file, $ZEROCAL_TOKEN or the simulator's), timeout (s per request), camera: where a
    driver with a camera service fetches captures (`--camera-service HOST:PORT`, `none`;
    None: its default)."""

    token: str
    timeout: float = 10.0
    camera: str | None = None


@dataclass(frozen=True)
class Driver:
    """One row of the table. connect(host, port, options) opens an adapter;
    camera_service: captures come from a camera service (`--camera-service`);
    no_rollback: why `hostpc rollback` does not apply (None: the controller keeps the
    offsets and their rollback ids); host_offsets: for a robot that keeps no zero offsets
    (its push is applied on the host for the session only), how to keep them ({run}: the
    run folder), None: the controller keeps what is pushed (hostpc.calibrate.outcome)."""

    name: str
    connect: Callable[[str, int, ConnectOptions], Awaitable[RobotAdapter]]
    camera_service: bool = False
    no_rollback: str | None = None
    host_offsets: str | None = None


async def _connect_zerocal(host: str, port: int, options: ConnectOptions) -> RobotAdapter:
    return await ZerocalAdapter.connect(host, port, token=options.token,
                                        timeout=options.timeout)


async def _connect_ur(host: str, port: int, options: ConnectOptions) -> RobotAdapter:
    return await ur.connect(host, port, timeout=options.timeout, camera=options.camera,
                            token=options.token)


DRIVERS: dict[str, Driver] = {
    "zerocal": Driver("zerocal", _connect_zerocal),
    "ur": Driver(
        "ur", _connect_ur, camera_service=True,
        no_rollback=(
            "rollback is not applicable to a UR (--driver ur): it has no writable zero "
            "offsets, so the calibration was applied on the host for that session only and "
            "nothing on the robot changed; to undo, stop loading the run's "
            "ur_calibration.yaml"),
        host_offsets=("load {run}/ur_calibration.yaml in the robot's UR/ROS setup (or "
                      "{run}/ur_offsets.script in its program; docs/calibrate.md, A UR)")),
}
DRIVER_NAMES = tuple(DRIVERS)
"""`--driver` choices."""
DEFAULT_DRIVER = "zerocal"
"""`--driver` when none is given."""
SIM_DRIVER = "zerocal"
"""The driver of `--robot sim`: the simulated controller (controller-stub) speaks our
protocol."""


def check_sim_driver(name: str) -> None:
    """InputError (one line, with the command that does it) if `--robot sim` is asked to
    run `--driver name`: the simulator speaks only SIM_DRIVER's protocol, and running it
    silently would calibrate with another driver than the one asked for."""
    if name == SIM_DRIVER:
        return
    stub = ("controller-stub serve --ur --port 0, then hostpc calibrate --robot "
            "127.0.0.1:PORT --driver ur (PORT: the port it prints)" if name == "ur"
            else f"a controller the {name} driver speaks to: --robot HOST:PORT --driver {name}")
    raise InputError(f"--robot sim --driver {name}: the simulator speaks only the "
                     f"{SIM_DRIVER} protocol; drop --driver for the simulator, or run "
                     f"{stub}")


def driver_named(name: str) -> Driver:
    """The table's row `name`; InputError listing the drivers if there is none."""
    try:
        return DRIVERS[name]
    except KeyError:
        raise InputError(f"--driver {name!r}: expected one of {', '.join(DRIVERS)}") from None
