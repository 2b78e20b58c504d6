"""Start and stop the simulated controller (`controller-stub serve`) as a subprocess.

`hostpc calibrate --robot sim` uses this: the stub runs on 127.0.0.1 with an OS-chosen
port (`--port 0`; the stub prints `listening on HOST:PORT`) and writes its hidden truth to a
file (`--truth-out`), which only the truth comparison of a simulated run reads. hostpc never
imports the simulator's code: it talks to it over the protocol like to any controller.

Each measurement kind declares its own default simulated world (`KindDescriptor.sim` in
`hostpc/kinds/<name>/__init__.py`, documented in docs/calibrate.md); a kind without one gets
stereo_target's. stereo_target and sphere_probe use the stub's packaged default scenario
(a UR5e with random zero errors within +-0.5 deg and one hidden physical effect, a 2 ms
probe trigger latency that only the touch probe sees) with `motion.time_scale` 0 (motions
take no wall time) and one surveyed frame, declared known by the simulated cell:
- stereo_target: `target.centre_error` zero, `target` known (makes joint 1 identifiable);
- sphere_probe: `probe.sphere_centre_error` zero, `sphere` known (makes joint 1
  identifiable).
dual_loop uses the packaged humanoid world (`humanoid.yaml`) with nothing known.

A kind that brings its own instrument (a plugin folder with a `sim_sensor.py`, docs/
measurement-models.md) has it simulated too: every `--plugin FOLDER` holding one is passed
to the stub as `--sensor-plugin FOLDER` (the stub imports only that file, never hostpc).

The token never touches the run folder or the process list: `scenario.json` is written
without `server.token`, and the stub gets the token in its environment ($ZEROCAL_TOKEN).

The stub's stdout (after its `listening on` line) and stderr go to `stub.log` in the
simulator's folder, so a chatty stub can never fill a pipe and block. On Linux the stub gets
PR_SET_PDEATHSIG (SIGTERM): if hostpc dies, even by SIGKILL, the stub is terminated too.
`hostpc calibrate --robot sim` starts the stub's process before its own imports and hands it
its arguments here (warm_stub.py): the same stub, its start-up overlapped with hostpc's.
`hostpc calibrate --robot sim --check` has the stub check the scenario instead
(`SimulatedController.check`: `serve --check`, which loads it as serving would and listens
on nothing), so the check refuses what the run would, by the simulator's own rules.
"""

from __future__ import annotations

import contextlib
import copy
import json
import os
import queue
import socket
import subprocess
import sys
import threading
from collections.abc import Iterable
from importlib import resources
from pathlib import Path
from typing import IO

import yaml

from hostpc.dataset.kind_registry import DEFAULT_METHOD, SimDefault, kind_descriptor
from hostpc.errors import ConnectionFailed, InputError
from hostpc.input_files import CONFIG, read_input_text
from hostpc.json_object import JsonObject
from hostpc.robots import warm_stub
from hostpc.robots.connect import TOKEN_ENV, RobotAddress, resolve_token

START_TIMEOUT_S = 30.0
STUB_LOG = "stub.log"
SENSOR_FILE = "sim_sensor.py"
"""A plugin folder's simulated sensor module (controller_stub/sensors/registry.py)."""


def _merge(base: JsonObject, overrides: JsonObject) -> JsonObject:
    """Deep-merge `overrides` into a copy of `base`."""
    merged = copy.deepcopy(base)
    for key, value in overrides.items():
        if isinstance(value, dict) and isinstance(merged.get(key), dict):
            merged[key] = _merge(merged[key], value)
        else:
            merged[key] = copy.deepcopy(value)
    return merged


def packaged_default_scenario(name: str = "default.yaml") -> JsonObject:
    """The stub's packaged scenario `name` (default: the default scenario) as a plain
    mapping (read as data, not code)."""
    text = (resources.files("controller_stub") / "scenarios" / name).read_text()
    data = yaml.safe_load(text) or {}
    if not isinstance(data, dict):
        raise InputError("controller_stub default scenario is not a mapping")
    return data


def sim_default(method: str | None = None, plugins: Iterable[str | Path] = ()) -> SimDefault:
    """The SimDefault of `method`'s kind (stereo_target's for None or a kind without one)."""
    descriptor = kind_descriptor(method, plugins) if method else None
    if descriptor is None or descriptor.sim is None:
        descriptor = kind_descriptor(DEFAULT_METHOD)
    assert descriptor is not None and descriptor.sim is not None
    return descriptor.sim


def default_sim_scenario(time_scale: float | None = None, method: str | None = None,
                         plugins: Iterable[str | Path] = ()) -> JsonObject:
    """The default world of `--robot sim --method METHOD` (see the module docstring), with
    the motion time scale set to `time_scale` if given."""
    default = sim_default(method, plugins)
    scenario = _merge(packaged_default_scenario(default.scenario), dict(default.overrides))
    if time_scale is not None:
        scenario = _merge(scenario, {"motion": {"time_scale": float(time_scale)}})
    return scenario


def sim_default_known(method: str | None = None, plugins: Iterable[str | Path] = ()
                      ) -> tuple[str, ...]:
    """Frames the default simulated cell of `method` declares as measured."""
    return sim_default(method, plugins).known


def load_scenario_file(path: str | Path, time_scale: float | None = 0.0) -> JsonObject:
    """A user's scenario file (YAML/JSON) as a mapping, with the motion time scale set
    (None keeps the file's). InputError naming the file if it cannot be read."""
    path = Path(path)
    text = read_input_text(path, CONFIG, f"--scenario {path}")  # regular file, bounded
    try:
        data = json.loads(text) if path.suffix.lower() == ".json" else yaml.safe_load(text)
    except (OSError, ValueError, yaml.YAMLError) as exc:
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise InputError(f"--scenario {path}: cannot read ({first})") from None
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise InputError(f"--scenario {path}: expected a mapping at the top level")
    if time_scale is not None:
        data = _merge(data, {"motion": {"time_scale": float(time_scale)}})
    return data


def _without_token(scenario: JsonObject) -> JsonObject:
    """A copy of `scenario` without `server.token` (what may be written to a run folder)."""
    server = scenario.get("server")
    if not isinstance(server, dict) or "token" not in server:
        return scenario
    return {**scenario, "server": {k: v for k, v in server.items() if k != "token"}}


def free_local_port(host: str = "127.0.0.1") -> int:
    """A TCP port that is free on `host` right now (for services such as the stub's Modbus
    server, whose port 0 means "off"); another process may take it before it is used."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind((host, 0))
        port: int = sock.getsockname()[1]
    return port


def _start_failure(returncode: int, message: str) -> InputError | ConnectionFailed:
    """The error of a stub that ended before listening: exit code 2 is its refusal of the
    scenario (one line, the stub's last)."""
    message = message or f"exit code {returncode}"
    if returncode == 2:  # the stub's exit code for a bad scenario
        return InputError(f"simulated controller refused the scenario: {message}")
    return ConnectionFailed(f"simulated controller failed to start: {message}")


class SimulatedController:
    """A `controller-stub serve` subprocess on 127.0.0.1 (port chosen by the OS).

        with SimulatedController(scenario, workdir) as sim:
            address = sim.address          # RobotAddress(host, port)
            truth = sim.truth()            # the stub's hidden truth (dict), current offsets

    scenario: the scenario mapping (written to `workdir/scenario.json` without its
    `server.token`); workdir: where the scenario, `truth.json` and the stub's output
    `stub.log` go; modbus_port: also serve the digital IO over Modbus TCP on this port
    (read-only; None: no Modbus server); token: the stub's token (default: the scenario's
    `server.token`, else $ZEROCAL_TOKEN, else the simulator's default), handed to the stub
    in its environment. `stop()` terminates only this process; the stub also ends when
    hostpc dies (Linux). plugins: the run's `--plugin` files and folders; the folders with
    a `sim_sensor.py` are the stub's `--sensor-plugin`s.
    """

    def __init__(self, scenario: JsonObject, workdir: str | Path,
                 modbus_port: int | None = None, token: str | None = None,
                 plugins: Iterable[str | Path] = ()) -> None:
        server = scenario.get("server")
        scenario_token = server.get("token") if isinstance(server, dict) else None
        self.token = token or (str(scenario_token) if scenario_token else resolve_token(None))
        self.scenario = scenario
        self.workdir = Path(workdir)
        self.scenario_path = self.workdir / "scenario.json"
        self.truth_path = self.workdir / "truth.json"
        self.log_path = self.workdir / STUB_LOG
        self.modbus_port = modbus_port
        self.sensor_folders = [Path(p).resolve() for p in plugins
                               if (Path(p) / SENSOR_FILE).is_file()]
        self.modbus_address: RobotAddress | None = None
        self.process: subprocess.Popen[str] | None = None
        self._address: RobotAddress | None = None
        self._log: IO[str] | None = None
        self._pump: threading.Thread | None = None

    @property
    def address(self) -> RobotAddress:
        """The simulator's address (after `start`)."""
        if self._address is None:
            raise RuntimeError("simulator not started")
        return self._address

    def start(self, timeout: float = START_TIMEOUT_S) -> RobotAddress:
        """Start the stub and wait for its `listening on HOST:PORT` line."""
        self.workdir.mkdir(parents=True, exist_ok=True)
        serve = [*self._serve_arguments(), "--truth-out", str(self.truth_path)]
        if self.modbus_port is not None:
            serve += ["--modbus-port", str(int(self.modbus_port))]
        self._log = log = open(self.log_path, "a", encoding="utf-8")  # noqa: SIM115
        warm = warm_stub.take()
        if warm is not None and warm_stub.hand_over(warm, serve, {TOKEN_ENV: self.token},
                                                    self.log_path):
            self.process = warm  # started at hostpc's start (warm_stub.py)
        else:
            self.process = subprocess.Popen(
                [sys.executable, "-m", "controller_stub", *serve], stdout=subprocess.PIPE,
                stderr=log, text=True,
                env={**os.environ, TOKEN_ENV: self.token},
                start_new_session=False, preexec_fn=warm_stub.die_with_parent(),  # noqa: PLW1509
            )
        lines: queue.Queue[str] = queue.Queue()
        stdout = self.process.stdout
        assert stdout is not None

        def pump() -> None:
            """Copy every line to the log; hand them over until `listening on`."""
            listening = False
            with contextlib.suppress(ValueError, OSError):  # the log or pipe was closed
                for line in stdout:
                    log.write(line)
                    log.flush()
                    if not listening:
                        listening = line.startswith("listening on ")
                        lines.put(line)
            lines.put("")

        self._pump = threading.Thread(target=pump, name="stub-output", daemon=True)
        self._pump.start()
        try:
            while True:
                line = lines.get(timeout=timeout).strip()
                if line.startswith("modbus on "):
                    host, _, port = line[len("modbus on "):].rpartition(":")
                    self.modbus_address = RobotAddress(sim=False, host=host, port=int(port))
                if line.startswith("listening on "):
                    host, _, port = line[len("listening on ") :].rpartition(":")
                    self._address = RobotAddress(sim=False, host=host, port=int(port))
                    return self._address
                if line == "":  # the stub closed its output: it is ending
                    break
        except queue.Empty:
            self.stop()
            raise ConnectionFailed(
                f"simulated controller did not start within {timeout:.0f} s"
            ) from None
        process, self.process = self.process, None
        try:
            returncode = warm_stub.wait_for_exit(process, timeout=10)
        except subprocess.TimeoutExpired:
            process.kill()
            returncode = process.wait(timeout=5)
        self._close_log()
        raise _start_failure(returncode, self._last_log_line())

    def check(self, timeout: float = START_TIMEOUT_S) -> None:
        """Have the stub load and check the scenario as `start` would (`serve --check`:
        nothing listens, no truth is written); InputError (one line) if it refuses it,
        ConnectionFailed if it cannot run. The scenario is written to `workdir`."""
        self.workdir.mkdir(parents=True, exist_ok=True)
        try:
            done = subprocess.run(
                [sys.executable, "-m", "controller_stub", *self._serve_arguments(), "--check"],
                capture_output=True, text=True, timeout=timeout,
                env={**os.environ, TOKEN_ENV: self.token})
        except subprocess.TimeoutExpired:
            raise ConnectionFailed(
                f"simulated controller did not check its scenario within {timeout:.0f} s"
            ) from None
        if done.returncode != 0:
            lines = done.stderr.strip().splitlines()
            raise _start_failure(done.returncode, lines[-1] if lines else "")

    def _serve_arguments(self) -> list[str]:
        """The stub's `serve` arguments for this scenario (written to `scenario_path`
        without its token), bound to 127.0.0.1 on a port the OS chooses."""
        self.scenario_path.write_text(json.dumps(_without_token(self.scenario), indent=2) + "\n")
        serve = ["serve", "--scenario", str(self.scenario_path), "--host", "127.0.0.1",
                 "--port", "0"]
        for folder in self.sensor_folders:
            serve += ["--sensor-plugin", str(folder)]
        return serve

    def _last_log_line(self) -> str:
        try:
            text = self.log_path.read_text(encoding="utf-8", errors="replace").strip()
        except OSError:
            return ""
        return text.splitlines()[-1] if text else ""

    def _close_log(self) -> None:
        log, self._log = self._log, None
        if log is not None:
            log.close()

    def truth(self) -> JsonObject:
        """The stub's hidden truth as last written (zero errors w.r.t. the CURRENT offsets)."""
        try:
            data = json.loads(self.truth_path.read_text())
        except (OSError, ValueError) as exc:
            raise ConnectionFailed(f"cannot read the simulator's truth: {exc}") from None
        if not isinstance(data, dict):
            raise ConnectionFailed("simulator truth file is not a JSON object")
        return data

    def stop(self) -> None:
        """Terminate the stub process (only ours) and wait for it."""
        process, self.process = self.process, None
        if process is not None:
            if process.poll() is None:
                process.terminate()
                try:
                    warm_stub.wait_for_exit(process, timeout=10)
                except subprocess.TimeoutExpired:
                    process.kill()
                    process.wait(timeout=5)
            if self._pump is not None:  # the pipe ends with the process
                self._pump.join(timeout=2.0)
            if process.stdout is not None:
                process.stdout.close()
        self._close_log()

    def __enter__(self) -> SimulatedController:
        if self._address is None:
            self.start()
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.stop()
