"""One calibration of the station, run as a `hostpc calibrate` child process.

A child process keeps every failure of a run (a crash, a hung driver, memory) out of the
long-running station, and runs exactly what a technician would run by hand: the run folder
is an ordinary `hostpc calibrate` run, resumable with `--resume`.
"""

from __future__ import annotations

import asyncio
import contextlib
import hashlib
import json
import os
import re
import signal
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from hostpc.calibrate.journal import JOURNAL_FILE
from hostpc.json_object import JsonObject
from hostpc.station.config import StationConfig
from hostpc.station.registers import OFFSETS_CHANGED_PREFIX, PUSH_LOST_PREFIX

_PROGRESS = re.compile(r"\]\s+(\S+)\s+(\d+)/(\d+)")
# progress bands of a run's phases, in percent
_PHASES = {"rig": (0, 15), "chessboard": (0, 15), "measure": (15, 75), "pose": (15, 75),
           "contact": (15, 75), "verify": (80, 100)}


def seed_of(serial: str) -> int:
    """A stable simulation seed for a robot serial (a simulated cell's robot identity)."""
    return int.from_bytes(hashlib.sha256(serial.encode()).digest()[:4], "big") % (2**31 - 1)


def sim_scenario(config: StationConfig, serial: str) -> JsonObject:
    """The scenario document of robot `serial`'s simulated world, as the run's scenario
    file gets it: its own scenario if the config names one, else the base scenario (or the
    packaged default) seeded by the serial."""
    from hostpc.robots.simulator import default_sim_scenario, load_scenario_file

    named = config.sim.scenarios_by_serial.get(serial)
    if named:
        return load_scenario_file(config.path(named))
    if config.sim.scenario:
        scenario = load_scenario_file(config.path(config.sim.scenario))
    else:
        scenario = default_sim_scenario()
    return {**scenario, "seed": seed_of(serial)}


CALIBRATE = [sys.executable, "-m", "hostpc.cli.main", "calibrate"]
OPTION_KEYS = {"--robot": "robot", "--driver": "driver", "--method": "method",
               "--poses": "poses", "--verify-poses": "verify_poses", "--effects": "effects",
               "--known": "known", "--require-joints": "require_joints", "--out": "runs_dir",
               "--swapped": "swapped", "--swap-limit": "swap_limit", "--scenario": "sim"}
"""The config key behind each `hostpc calibrate` option the station sets itself; any other
option comes from `calibrate_args`."""


def calibrate_options(config: StationConfig, run_dir: Path,
                      scenario_file: Path | None = None) -> list[str]:
    """The `hostpc calibrate` options of a new run in `run_dir` (with the simulated robot's
    `scenario_file`): the config's keys, then `calibrate_args` verbatim. Every run writes
    its report.html."""
    options = ["--robot", config.robot, "--driver", config.driver, "--method", config.method,
               "--poses", str(config.poses), "--verify-poses", str(config.verify_poses),
               "--out", str(run_dir)]
    if config.effects:
        options += ["--effects", config.effects]
    if config.known:
        options += ["--known", config.known]
    if config.require_joints:
        options += ["--require-joints", config.require_joints]
    if config.swapped:
        options += ["--swapped", config.swapped]
    if config.swap_limit is not None:
        options += ["--swap-limit", f"{config.swap_limit:g}"]
    if scenario_file is not None:
        options += ["--scenario", str(scenario_file)]
    return [*options, *config.calibrate_args]


def resume_options(config: StationConfig, run_dir: Path, push_again: bool = False
                   ) -> list[str]:
    """The `hostpc calibrate` options that resume the run in `run_dir`: `--resume DIR`, and
    `--push` when its push is lost (`push_again`: a resume found the controller at the
    run's previous offsets again, PREVIOUS) or for a simulated robot whose run had pushed
    (its simulated controller ended with the run, so a resume restarts it with its initial
    offsets: without `--push` the push is lost and never verified)."""
    options = ["--resume", str(run_dir)]
    if push_again or (config.robot == "sim" and push_in_flight(run_dir)):
        options.append("--push")
    return options


def resume_text(config: StationConfig, run_dir: Path, push_again: bool = False) -> str:
    """The command a technician types to resume the run in `run_dir` and archive it."""
    return " ".join(["hostpc calibrate", *resume_options(config, run_dir, push_again),
                     "--db", config.database_url()])


def calibrate_command(config: StationConfig, run_dir: Path, serial: str,
                      resume: bool, push_again: bool = False) -> list[str]:
    """The `hostpc calibrate` command line of one run (or of its resume)."""
    if resume:
        return [*CALIBRATE, *resume_options(config, run_dir, push_again)]
    scenario_file = None
    if config.robot == "sim":
        scenario_file = run_dir.parent / ".scenarios" / f"{run_dir.name}.json"
        scenario_file.parent.mkdir(parents=True, exist_ok=True)
        scenario_file.write_text(json.dumps(sim_scenario(config, serial), indent=1))
    return [*CALIBRATE, *calibrate_options(config, run_dir, scenario_file)]


def _last_push_event(run_dir: Path) -> JsonObject | None:
    """The run journal's last line among push_intent, push, result and rollback (None if
    none). Read only (the child may be appending: an unfinished last line is skipped,
    never cut)."""
    try:
        data = (run_dir / JOURNAL_FILE).read_bytes()
    except OSError:
        return None
    last = None
    for raw in data.splitlines(keepends=True):
        if not raw.endswith(b"\n") or b'"event":"sample"' in raw:
            continue
        with contextlib.suppress(ValueError):
            obj = json.loads(raw)
            event = obj.get("event") if isinstance(obj, dict) else None
            if event in ("push_intent", "push", "result", "rollback"):
                last = obj
    return last


def push_in_flight(run_dir: Path) -> bool:
    """True if the run's journal holds a push (or a push intent) not followed by the run's
    result or a rollback: the controller may hold offsets nobody verified yet."""
    last = _last_push_event(run_dir)
    return last is not None and last.get("event") in ("push_intent", "push")


def push_not_stored(run_dir: Path) -> bool:
    """True if the push in flight (`push_in_flight`) is one the controller did not store as
    asked (its `push` event has `held_offsets`, the offsets read back: hostpc.calibrate.
    push.PushMismatch): a resume fails on it again, only a rollback settles it."""
    last = _last_push_event(run_dir)
    return last is not None and last.get("event") == "push" and "held_offsets" in last


PREVIOUS, OTHER = "previous", "other"
"""What a resume of a pending run found the controller holding (`controller_held`)."""


def controller_held(code: int, error: str) -> str:
    """What the controller holds, as a resume of a run with a push in flight found it:
    the resume compares the controller's offsets now with the run's journal (its previous
    and pushed ones) and its exit says which. PREVIOUS: the run's previous offsets again,
    its push lost (exit 4, "push lost: ..."); OTHER: neither its previous nor its pushed
    ones (exit 2, "the controller's zero offsets changed since the run ..."): no resume
    settles the run; "": anything else (the pushed offsets, or not read)."""
    if code == 4 and error.startswith(PUSH_LOST_PREFIX):
        return PREVIOUS
    if code == 2 and error.startswith(OFFSETS_CHANGED_PREFIX):
        return OTHER
    return ""


def error_line(line: str) -> str | None:
    """The reason in a line of `hostpc calibrate`'s output ("hostpc calibrate: error: ..."
    or "hostpc calibrate: interrupted ..."), or None."""
    for prefix in ("hostpc calibrate: error: ", "hostpc calibrate: "):
        if line.startswith(prefix) and ("error:" in line or "interrupted" in line):
            return line[len(prefix):].strip()
    return None


@dataclass
class ChildRun:
    """A running `hostpc calibrate`; `progress` is 0..100, `last_line` its last output line,
    `error` the reason of its last error line ("hostpc calibrate: error: ...")."""

    process: asyncio.subprocess.Process
    progress: int = 0
    last_line: str = ""
    error: str = ""

    def interrupt(self) -> None:
        """Ask the run to stop at a safe point (SIGINT: the run stays resumable)."""
        if self.process.returncode is None:
            self.process.send_signal(signal.SIGINT)


async def start_child(command: list[str], log_path: Path, on_progress: Callable[[int, str], None]
                      ) -> tuple[ChildRun, asyncio.Task[int]]:
    """Start `command`; its output goes to `log_path`; returns the child and a task that
    finishes with its exit code."""
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    process = await asyncio.create_subprocess_exec(
        *command, stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.STDOUT, env=env,
        cwd=os.getcwd())
    child = ChildRun(process)

    async def pump() -> int:
        assert process.stdout is not None
        with log_path.open("ab") as log:
            async for raw in process.stdout:
                log.write(raw)
                log.flush()
                line = raw.decode(errors="replace").rstrip()
                if line:
                    child.last_line = line
                    child.error = error_line(line) or child.error
                match = _PROGRESS.search(line)
                if match:
                    phase, done, total = match.group(1), int(match.group(2)), int(match.group(3))
                    low, high = _PHASES.get(phase, (child.progress, child.progress))
                    if total > 0 and high > low:
                        child.progress = max(child.progress, low + (high - low) * done // total)
                on_progress(child.progress, child.last_line)
        return await process.wait()

    return child, asyncio.create_task(pump())


