"""The station's whole configuration, checked when it starts (docs/station.md "Checked at
start"): a station that would fail every run refuses to start instead, with one line
naming the config key (InputError, exit code 2).

Checked here: `runs_dir` (a folder the station can write), the simulated cell's scenario
files (`sim`), and everything the station passes to `hostpc calibrate` (its keys and
`calibrate_args`: the rig, the cell, the reference, effects, token file, ...), by running
`hostpc calibrate ... --check`, the same pre-flight checks a run makes before it connects.
The archive (`db`) and the ports (`modbus`, `http`) are checked by opening them
(`Station.open`, `hostpc station`'s page).
"""

from __future__ import annotations

import os
import re
import subprocess

from hostpc.errors import InputError, ZerocalError
from hostpc.station.config import StationConfig
from hostpc.station.runner import CALIBRATE, OPTION_KEYS, calibrate_options, sim_scenario

CHECK_TIMEOUT_S = 120.0
_OPTION = re.compile(r"--[a-z][a-z-]*")


def check_station_config(config: StationConfig, source: str) -> None:
    """InputError "SOURCE: KEY: what is wrong" for the first problem found."""
    _check_runs_dir(config, source)
    if config.robot == "sim":
        _check_sim(config, source)
    _check_calibrate(config, source)


def _check_runs_dir(config: StationConfig, source: str) -> None:
    """The runs folder exists and is writable, or can be created (nothing is created
    here: a station that refuses to start leaves nothing behind)."""
    folder = config.path(config.runs_dir).absolute()
    existing = next(p for p in (folder, *folder.parents) if p.exists())
    if not existing.is_dir():
        raise InputError(f"{source}: runs_dir: {folder}: {existing} is not a folder")
    if not os.access(existing, os.W_OK | os.X_OK):
        what = "not writable" if existing == folder else f"cannot be created in {existing}"
        raise InputError(f"{source}: runs_dir: {folder}: {what}")


def _check_sim(config: StationConfig, source: str) -> None:
    named = [("sim.scenario", "")] if config.sim.scenario else []
    named += [(f"sim.scenarios_by_serial.{serial}", serial)
              for serial in config.sim.scenarios_by_serial]
    for key, serial in named:
        try:
            sim_scenario(config, serial or "check")
        except ZerocalError as exc:
            raise InputError(f"{source}: {key}: {exc}") from None


def _check_calibrate(config: StationConfig, source: str) -> None:
    check_dir = config.path(config.runs_dir) / ".check"  # named, never created
    command = [*CALIBRATE, *calibrate_options(config, check_dir), "--check"]
    try:
        done = subprocess.run(command, capture_output=True, text=True, timeout=CHECK_TIMEOUT_S,
                              cwd=os.getcwd(), check=False)
    except (OSError, subprocess.TimeoutExpired) as exc:
        raise InputError(f"{source}: calibrate_args: cannot run hostpc calibrate --check "
                         f"({exc})") from None
    if done.returncode == 0:
        return
    lines = [line for line in done.stderr.splitlines() if line.strip()]
    message = lines[-1] if lines else f"hostpc calibrate --check exited {done.returncode}"
    for prefix in ("hostpc calibrate: error: ", "hostpc calibrate: "):
        if message.startswith(prefix):
            message = message[len(prefix):]
            break
    option = next((o for o in _OPTION.findall(message) if o in OPTION_KEYS
                   or o in config.calibrate_args), None)
    key = OPTION_KEYS.get(option or "", "calibrate_args")
    raise InputError(f"{source}: {key}: {message}")

