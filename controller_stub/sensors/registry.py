"""The registry of simulated instruments a measurement kind brings with it (`sensor_read`).

The built-in kinds' sensors (tracker, cameras, probe) have their own protocol calls. Any
other instrument is served through one generic request, `sensor_read {sensor, request}` ->
`sensor_reading {reading}` (protocol/measurement_messages.py), answered by a simulated
sensor found here. A kind adds one without editing the stub:

- a module `sim_sensor.py` in the kind's folder, loaded with `controller-stub serve
  --sensor-plugin FOLDER` (`hostpc calibrate --robot sim --plugin FOLDER` passes it on),
  defining ``SIM_SENSORS = {"name": factory}``; it may import numpy and controller_stub,
  never hostpc (the stub's truth must not share code with the fitter: the CLI refuses a
  sensor module that imports it);
- or an installed package's entry point in the group ``zerocal.sim_sensors``
  (``name = "module:factory"``).

The interface, all a sensor sees of the simulation::

    factory(setup: SensorSetup) -> SimSensor        # once per simulation, on first read
    setup.world.flange_pose() -> (4, 4)              # TRUE T_base_flange now (m)
    setup.world.joint_positions() -> (n,)            # reported joint angles now (rad)
    setup.world.time -> float                        # controller clock (s)
    setup.settings -> mapping                        # the scenario's `sensors.<name>`
    setup.seed -> int ; setup.rng -> Generator       # the scenario's seed; the sensor's own
                                                     # noise stream (seed and name)
    sensor.read(request: dict) -> dict               # one reading, JSON values only;
                                                     # SensorRequestError: not a request
                                                     # this sensor reads (-> bad_message)
    sensor.truth() -> dict                           # its hidden truth (for tests)

The server settles the robot before every reading (it measures the robot, as a capture
does: the clock waits out what is left of `motion.settle_s` since the robot last moved),
adds the joint angles and the clock at its start to it, and charges `motion.capture_s` for
it, as for any measurement. Never imports hostpc.
"""

from __future__ import annotations

import importlib.util
import sys
import zlib
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from functools import cache
from importlib.metadata import entry_points
from pathlib import Path
from typing import Any, Protocol

import numpy as np

ENTRY_POINT_GROUP = "zerocal.sim_sensors"
SENSOR_FILE = "sim_sensor.py"
"""The module of a kind's folder that holds its simulated sensors (``SIM_SENSORS``)."""


class SensorWorld(Protocol):
    """What a simulated sensor reads of the simulated robot (the arm `Simulation`)."""

    @property
    def time(self) -> float: ...
    def flange_pose(self) -> np.ndarray: ...
    def joint_positions(self) -> np.ndarray: ...


@dataclass(frozen=True)
class SensorSetup:
    """What a sensor's factory gets: see the module docstring."""

    name: str
    world: SensorWorld
    settings: Mapping[str, Any]
    seed: int
    rng: np.random.Generator


class SimSensor(Protocol):
    """A simulated instrument (see the module docstring)."""

    def read(self, request: Mapping[str, Any]) -> dict[str, Any]: ...
    def truth(self) -> dict[str, Any]: ...


SensorFactory = Callable[[SensorSetup], SimSensor]


class SensorRequestError(ValueError):
    """A request the sensor cannot read (its message says why, in one line)."""


class UnknownSensor(LookupError):
    """No simulated sensor of that name (or none on this simulated robot)."""


class SensorPluginError(ValueError):
    """A sensor plugin folder or entry point that cannot be loaded (one line)."""


def sensor_stream(seed: int, name: str) -> np.random.Generator:
    """The noise stream of sensor `name`: the scenario's seed and the name (stable across
    runs and Python versions; distinct from the built-in streams' small ids)."""
    return np.random.default_rng([int(seed), 0x5E45, zlib.crc32(name.encode())])


def load_sensor_folder(folder: str | Path) -> dict[str, SensorFactory]:
    """The ``SIM_SENSORS`` of ``FOLDER/sim_sensor.py``, imported alone (not the kind's
    package, whose ``__init__`` belongs to the host); SensorPluginError in one line."""
    path = Path(folder) / SENSOR_FILE
    if not path.is_file():
        raise SensorPluginError(f"--sensor-plugin {folder}: no {SENSOR_FILE}")
    name = f"zerocal_sim_sensor_{zlib.crc32(str(path.resolve()).encode()):08x}"
    spec = importlib.util.spec_from_file_location(name, path)
    if spec is None or spec.loader is None:
        raise SensorPluginError(f"--sensor-plugin {folder}: cannot import {SENSOR_FILE}")
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    try:
        spec.loader.exec_module(module)
    except Exception as exc:
        sys.modules.pop(name, None)
        raise SensorPluginError(f"--sensor-plugin {folder}: {SENSOR_FILE} failed to import: "
                                f"{type(exc).__name__}: {exc}") from exc
    sensors = getattr(module, "SIM_SENSORS", None)  # a user's module: its one published name
    if not isinstance(sensors, Mapping) or not all(
            isinstance(k, str) and callable(v) for k, v in sensors.items()):
        raise SensorPluginError(f"--sensor-plugin {folder}: {SENSOR_FILE} defines no "
                                "SIM_SENSORS = {name: factory}")
    return dict(sensors)


@cache
def installed_sensors() -> tuple[tuple[str, Any], ...]:
    """(name, loaded object) of the entry points of group ``zerocal.sim_sensors``, scanned
    once per process (a scan reads every installed distribution's metadata, ~10 ms, and
    every server the tests start would pay it)."""
    found = []
    for entry in entry_points(group=ENTRY_POINT_GROUP):
        try:
            found.append((entry.name, entry.load()))
        except Exception as exc:
            raise SensorPluginError(f"entry point {entry.name}: failed to load: {exc}") from exc
    return tuple(found)


def sensor_factories(folders: Iterable[str | Path] = ()) -> dict[str, SensorFactory]:
    """Every simulated sensor: the installed entry points (group ``zerocal.sim_sensors``),
    then the plugin folders; a name given twice is a SensorPluginError."""
    found: dict[str, SensorFactory] = {}

    def add(name: str, factory: Any, source: str) -> None:
        if name in found:
            raise SensorPluginError(f"{source}: simulated sensor {name!r} is already "
                                    "registered")
        if not callable(factory):
            raise SensorPluginError(f"{source}: {name!r} is not a sensor factory")
        found[name] = factory

    for name, factory in installed_sensors():
        add(name, factory, f"entry point {name}")
    for folder in folders:
        for name, factory in load_sensor_folder(folder).items():
            add(name, factory, f"--sensor-plugin {folder}")
    return found


class SimSensors:
    """The simulated sensors of one simulation, each made on its first read.

    factories: by name (`sensor_factories`); world: the robot they measure (None: a
    simulation they cannot measure, e.g. the humanoid: every read is UnknownSensor);
    settings: the scenario's `sensors` section; seed: the scenario's seed."""

    def __init__(self, factories: Mapping[str, SensorFactory], world: SensorWorld | None,
                 settings: Mapping[str, Mapping[str, Any]], seed: int) -> None:
        self.factories = dict(factories)
        self.world = world
        self.settings = settings
        self.seed = seed
        self._made: dict[str, SimSensor] = {}

    def sensor(self, name: str) -> SimSensor:
        """The sensor `name` (made now if it is its first read); UnknownSensor otherwise."""
        if name in self._made:
            return self._made[name]
        factory = self.factories.get(name)
        if factory is None or self.world is None:
            offered = ", ".join(sorted(self.factories)) if self.world is not None else ""
            raise UnknownSensor(f"no simulated sensor {name!r} (simulated: {offered or 'none'})")
        made = factory(SensorSetup(name=name, world=self.world,
                                   settings=self.settings.get(name, {}), seed=self.seed,
                                   rng=sensor_stream(self.seed, name)))
        self._made[name] = made
        return made

    def truth(self) -> dict[str, Any]:
        """The hidden truth of every sensor made so far, by name."""
        return {name: sensor.truth() for name, sensor in self._made.items()}
