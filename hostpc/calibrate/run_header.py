"""The header of a calibration run as one frozen value: ``RunHeader`` (``run.json``).

Written when the run starts and again when its plan is fixed (or `--known` changes on a
resume): what the run is (robot, serial, settings, seed, cell) and where the robot was
(``InitialState``). A resume reads it back (``read_run_header``) to continue with the same
settings and plan; a rollback reads it to derive the run's outcome again. ``to_dict`` is
run.json without its format line (Journal.write_header adds it), its keys in the order they
always had. The cell stays in its JSON form (``Cell.to_dict()``): rebuilding it needs the
run's plugins (``cell_from_dict``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from hostpc.calibrate.journal import Journal
from hostpc.calibrate.run_values import RobotInfo
from hostpc.calibrate.swaps import DEFAULT_SWAP_LIMIT_DEG
from hostpc.errors import InputError
from hostpc.json_object import JsonObject
from hostpc.methods.base import Plan, RunSettings


@dataclass(frozen=True)
class InitialState:
    """Where the robot was when the run started: its model, joint angles and zero offsets
    (rad), joint limits, controller time (None if not finite) and camera description."""

    robot: str
    q: tuple[float, ...]
    zero_offsets: tuple[float, ...]
    q_min: tuple[float, ...]
    q_max: tuple[float, ...]
    time: float | None
    camera: Any  # the controller's camera description, as it reported it (JSON)

    @property
    def offsets(self) -> np.ndarray:
        """(n,) rad the controller's zero offsets at the start."""
        return np.asarray(self.zero_offsets, float)

    def to_dict(self) -> JsonObject:
        return {"robot": self.robot, "q": list(self.q), "zero_offsets": list(self.zero_offsets),
                "q_min": list(self.q_min), "q_max": list(self.q_max), "time": self.time,
                "camera": self.camera}

    @classmethod
    def from_dict(cls, data: JsonObject) -> InitialState:
        return cls(str(data.get("robot", "")), tuple(data.get("q", ())),
                   tuple(data["zero_offsets"]), tuple(data.get("q_min", ())),
                   tuple(data.get("q_max", ())), data.get("time"), data.get("camera"))


@dataclass(frozen=True)
class RunHeader:
    """A run's header (module docstring); plan: None until the poses are planned."""

    created: str
    robot: RobotInfo
    robot_serial: str | None
    settings: RunSettings
    cell: JsonObject  # Cell.to_dict()
    initial: InitialState
    plan: Plan | None = None
    archive: str | None = None
    """The results archive the run is archived in (`--db`), its URL without a password
    (hostpc.db_url.redacted_url): a next command names it, so the archive follows."""

    @property
    def seed(self) -> int:
        return self.settings.seed

    def to_dict(self) -> JsonObject:
        document: JsonObject = {
            "created": self.created, "robot": self.robot.to_dict(),
            "robot_serial": self.robot_serial, "settings": self.settings.to_dict(),
            "seed": self.seed, "cell": dict(self.cell), "initial": self.initial.to_dict()}
        if self.plan is not None:
            document["plan"] = self.plan.to_dict()
        if self.archive is not None:
            document["archive"] = self.archive
        return document

    @classmethod
    def from_dict(cls, data: JsonObject) -> RunHeader:
        """run.json read back (an older version's too: absent values take their defaults)."""
        robot = data.get("robot") or {}
        return cls(
            created=str(data.get("created", "")),
            robot=RobotInfo(str(robot.get("address", "")), str(robot.get("driver", "zerocal")),
                            bool(robot.get("sim", False)), robot.get("scenario")),
            robot_serial=data.get("robot_serial"),
            settings=RunSettings.from_dict(data["settings"]),
            cell=data.get("cell") or {}, initial=InitialState.from_dict(data["initial"]),
            plan=Plan.from_dict(data["plan"]) if "plan" in data else None,
            archive=data.get("archive"))

    def robot_argument(self) -> str:
        """How a new run would name this run's robot: `sim` or its address."""
        return "sim" if self.robot.sim else (self.robot.address or "ROBOT")

    def new_run_options(self) -> str:
        """The options of a new run of this robot and cell (a next command's start):
        the robot, the method, a simulated run's world (its scenario, as the run kept it)
        its seed, and a declared swap."""
        words = ["--robot", self.robot_argument(), "--method", self.settings.method]
        if self.robot.sim and self.robot.scenario:
            words += ["--scenario", str(self.robot.scenario)]
        if self.settings.swapped:
            words += ["--swapped", ",".join(f"J{j}" for j in self.settings.swapped)]
            if self.settings.swap_limit_deg != DEFAULT_SWAP_LIMIT_DEG:
                words += ["--swap-limit", f"{self.settings.swap_limit_deg:g}"]
        words += ["--seed", str(self.seed)]
        return " ".join(words)


def read_run_header(journal: Journal) -> RunHeader:
    """The run header of `journal`'s folder (InputError if it is missing or broken)."""
    return parse_run_header(journal.read_header(), journal)


def parse_run_header(data: JsonObject, journal: Journal) -> RunHeader:
    """`data` (``journal.read_header()``) as a RunHeader (InputError if it is broken)."""
    try:
        return RunHeader.from_dict(data)
    except (KeyError, TypeError, ValueError, IndexError) as exc:
        raise InputError(f"{journal.run_path}: not a calibration run header ({exc!r})") from None
