"""The plain values of a calibration run: how it reaches its robot, and what it produced."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from hostpc.calibrate.push import PushPlan
from hostpc.calibrate.run_result import RunResult
from hostpc.calibrate.verify import VerifyResult
from hostpc.dataset import Dataset
from hostpc.fitting import FitResult
from hostpc.json_object import JsonObject


@dataclass(frozen=True)
class RobotInfo:
    """How the run reaches its robot: the address text, the driver, simulated or not, and
    the simulated scenario file (for a resume of a simulated run)."""

    address: str
    driver: str = "zerocal"
    sim: bool = False
    scenario: str | None = None

    def to_dict(self) -> JsonObject:
        return {"address": self.address, "driver": self.driver, "sim": self.sim,
                "scenario": self.scenario}


@dataclass
class RunOutcome:
    """What a run produced. run: its result (result.json); summary: the human text."""

    run_dir: Path
    run: RunResult
    summary: str
    exit_code: int
    fit: FitResult | None = None
    dataset: Dataset | None = None
    verify: VerifyResult | None = None
    push: PushPlan | None = None

    @property
    def document(self) -> JsonObject:
        """The result's JSON form (result.json; `hostpc calibrate --json` prints it)."""
        return self.run.to_dict()
