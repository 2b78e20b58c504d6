"""Start and stop the simulated controller (`controller-stub serve`) as a subprocess.

`hostpc calibrate --robot sim` uses this: the stub runs on 127.0.0.1 with an OS-chosen
port (`--port 0`; the stub prints `listening on HOST:PORT`) and writes its hidden truth to a
file (`--truth-out`), which only the truth comparison of a simulated run reads. hostpc never
imports the simulator's code: it talks to it over the protocol like to any controller.

The default simulated world is the stub's packaged default scenario (a UR5e with random
zero errors within +-0.5 deg and one hidden physical effect, a probe trigger latency), with
two changes documented in docs/calibrate.md:
- `motion.time_scale` 0: motions take no wall time (the run is fast);
- `target.centre_error` zero: the target's position in the base frame was surveyed, so the
  cell declares it known (`SIM_DEFAULT_KNOWN`), which makes joint 1 identifiable.
"""

from __future__ import annotations

import copy
import json
import queue
import subprocess
import sys
import threading
from importlib import resources
from pathlib import Path
from typing import Any

import yaml

from hostpc.errors import ConnectionFailed, InputError
from hostpc.robots.connect import RobotAddress

SIM_DEFAULT_KNOWN: tuple[str, ...] = ("target",)
"""Frames the default simulated cell declares as measured (see the module docstring)."""
SIM_DEFAULT_OVERRIDES: dict[str, Any] = {
    "motion": {"time_scale": 0.0},
    "target": {"centre_error": [0.0, 0.0, 0.0]},
}
SIM_METHOD_SCENARIOS: dict[str, str] = {"dual_loop": "humanoid.yaml"}
"""Methods whose `--robot sim` world is another packaged scenario (used as packaged, with
only the motion time scale set, and nothing declared known): dual_loop's humanoid."""
START_TIMEOUT_S = 30.0


def _merge(base: dict[str, Any], overrides: dict[str, Any]) -> dict[str, Any]:
    """Deep-merge `overrides` into a copy of `base`."""
    merged = copy.deepcopy(base)
    for key, value in overrides.items():
        if isinstance(value, dict) and isinstance(merged.get(key), dict):
            merged[key] = _merge(merged[key], value)
        else:
            merged[key] = copy.deepcopy(value)
    return merged


def packaged_default_scenario(name: str = "default.yaml") -> dict[str, Any]:
    """The stub's packaged scenario `name` (default: the default scenario) as a plain
    mapping (read as data, not code)."""
    text = (resources.files("controller_stub") / "scenarios" / name).read_text()
    data = yaml.safe_load(text) or {}
    if not isinstance(data, dict):
        raise InputError("controller_stub default scenario is not a mapping")
    return data


def default_sim_scenario(time_scale: float | None = None,
                         method: str | None = None) -> dict[str, Any]:
    """The default world of `--robot sim` (see the module docstring); for a method in
    SIM_METHOD_SCENARIOS its own packaged scenario."""
    packaged = SIM_METHOD_SCENARIOS.get(method or "")
    if packaged is not None:
        scenario = packaged_default_scenario(packaged)
    else:
        scenario = _merge(packaged_default_scenario(), SIM_DEFAULT_OVERRIDES)
    if time_scale is not None:
        scenario = _merge(scenario, {"motion": {"time_scale": float(time_scale)}})
    return scenario


def sim_default_known(method: str | None = None) -> tuple[str, ...]:
    """Frames the default simulated cell of `method` declares as measured."""
    return () if (method or "") in SIM_METHOD_SCENARIOS else SIM_DEFAULT_KNOWN


def load_scenario_file(path: str | Path, time_scale: float | None = 0.0) -> dict[str, Any]:
    """A user's scenario file (YAML/JSON) as a mapping, with the motion time scale set
    (None keeps the file's). InputError naming the file if it cannot be read."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
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


class SimulatedController:
    """A `controller-stub serve` subprocess on 127.0.0.1 (port chosen by the OS).

        with SimulatedController(scenario, workdir) as sim:
            address = sim.address          # RobotAddress(host, port)
            truth = sim.truth()            # the stub's hidden truth (dict), current offsets

    scenario: the scenario mapping (written to `workdir/scenario.json`); workdir: where the
    scenario and `truth.json` go. `stop()` terminates only this process.
    """

    def __init__(self, scenario: dict[str, Any], workdir: str | Path) -> None:
        self.scenario = scenario
        self.workdir = Path(workdir)
        self.scenario_path = self.workdir / "scenario.json"
        self.truth_path = self.workdir / "truth.json"
        self.process: subprocess.Popen[str] | None = None
        self._address: RobotAddress | None = None

    @property
    def address(self) -> RobotAddress:
        """The simulator's address (after `start`)."""
        if self._address is None:
            raise RuntimeError("simulator not started")
        return self._address

    def start(self, timeout: float = START_TIMEOUT_S) -> RobotAddress:
        """Start the stub and wait for its `listening on HOST:PORT` line."""
        self.workdir.mkdir(parents=True, exist_ok=True)
        self.scenario_path.write_text(json.dumps(self.scenario, indent=2) + "\n")
        command = [
            sys.executable, "-m", "controller_stub", "serve",
            "--scenario", str(self.scenario_path), "--host", "127.0.0.1", "--port", "0",
            "--truth-out", str(self.truth_path),
        ]  # fmt: skip
        self.process = subprocess.Popen(
            command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
        )
        lines: queue.Queue[str] = queue.Queue()
        stdout = self.process.stdout
        assert stdout is not None

        def pump() -> None:
            for line in stdout:
                lines.put(line)
            lines.put("")

        threading.Thread(target=pump, daemon=True).start()
        try:
            while True:
                line = lines.get(timeout=timeout).strip()
                if line.startswith("listening on "):
                    host, _, port = line[len("listening on ") :].rpartition(":")
                    self._address = RobotAddress(sim=False, host=host, port=int(port))
                    return self._address
                if line == "" and self.process.poll() is not None:
                    break
        except queue.Empty:
            self.stop()
            raise ConnectionFailed(
                f"simulated controller did not start within {timeout:.0f} s"
            ) from None
        process, self.process = self.process, None
        returncode = process.wait(timeout=5)
        stderr = process.stderr.read().strip() if process.stderr else ""
        message = stderr.splitlines()[-1] if stderr else f"exit code {returncode}"
        if returncode == 2:  # the stub's exit code for a bad scenario
            raise InputError(f"simulated controller refused the scenario: {message}")
        raise ConnectionFailed(f"simulated controller failed to start: {message}")

    def truth(self) -> dict[str, Any]:
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
        if process is None:
            return
        if process.poll() is None:
            process.terminate()
            try:
                process.wait(timeout=10)
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait(timeout=5)
        for stream in (process.stdout, process.stderr):
            if stream is not None:
                stream.close()

    def __enter__(self) -> SimulatedController:
        if self._address is None:
            self.start()
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.stop()
