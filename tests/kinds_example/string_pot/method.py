"""string_pot's acquisition: move, read the cable length through ``sensor_read``.

The instrument is the kind's own: its method reads it by name through the generic
capability (``hostpc.robots.base.sensors_of(robot).read_sensor("string_pot", request)``),
which the zerocal driver offers over the protocol and ``--record`` / ``--replay`` tape.
The request and reading are the contract with ``sim_sensor.py`` (its docstring).

Planning: random poses within the joint limits whose nominal cable length is inside the
instrument's range (the runner's D-optimal selection picks from them). Each reading
averages ``AVERAGE`` readings. Frames: the hook in the flange (``tool``) and the drum in
the robot base frame (``anchor``), nominal values from the instrument's description (kept
in the run folder for a resume).
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from hostpc.dataset import Dataset, RobotDescription, Samples, dataset_to_dict
from hostpc.errors import ControllerError
from hostpc.files import write_json_atomic
from hostpc.kinematics import forward, get_robot
from hostpc.methods.base import Method, Phase, Progress, SampleRecord, floats, move_or_skip
from hostpc.robots.base import Need, RobotAdapter, RobotState, sensors_of

SENSOR = "string_pot"
DESCRIPTION_FILE = "string_pot.json"
AVERAGE = 4
RANGE_MARGIN = 0.9
"""Candidates keep the nominal cable length below this fraction of the range."""
FRAMES = ("tool", "anchor")


@dataclass(frozen=True)
class CableLength:
    """One sample: the joint angles at the reading (rad), the cable length and its sigma
    (m); journaled in its dataset-file form (``to_json``)."""

    q: tuple[float, ...]
    length: float
    sigma: float

    def to_json(self) -> dict[str, Any]:
        return {"q": list(self.q), "length": self.length, "sigma": self.sigma}

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> CableLength:
        return cls(floats(data["q"]), float(data["length"]), float(data["sigma"]))


class StringPotMethod(Method):
    """See the module docstring."""

    name: ClassVar[str] = "string_pot"
    needs: ClassVar[tuple[Need, ...]] = (Need.SENSORS,)

    def __init__(self, settings: Any, cell: Any, run_dir: Path) -> None:
        super().__init__(settings, cell, run_dir)
        self._chain = get_robot(cell.robot)
        self._description: dict[str, Any] | None = None

    async def prepare(self, robot: RobotAdapter, progress: Progress) -> None:
        """The instrument's description (nominal drum and hook, noise, range)."""
        path = self.run_dir / DESCRIPTION_FILE
        if path.is_file():
            self._description = json.loads(path.read_text(encoding="utf-8"))
            return
        reading = await sensors_of(robot, f"--method {self.name}").read_sensor(
            SENSOR, {"what": "describe"})
        self._description = dict(reading.reading)
        write_json_atomic(path, self._description)

    def _nominal(self, key: str) -> np.ndarray:
        if self._description is None:
            raise ControllerError("string_pot: prepare() was not run")
        return np.asarray(self._description[key], float)

    def _lengths(self, q: np.ndarray) -> np.ndarray:
        T = forward(self._chain, q).T_base_flange
        hook = np.einsum("nij,j->ni", T[:, :3, :3], self._nominal("tool")) + T[:, :3, 3]
        lengths: np.ndarray = np.linalg.norm(hook - self._nominal("anchor"), axis=1)
        return lengths

    def candidates(self, state: RobotState, rng: np.random.Generator) -> np.ndarray:
        """Random poses within the limits (10 deg margin) inside the cable's range."""
        margin = math.radians(10.0)
        low = np.maximum(state.q_min + margin, -math.pi)
        high = np.minimum(state.q_max - margin, math.pi)
        q = rng.uniform(low, high, size=(2 * self.settings.n_candidates, low.size))
        reach = RANGE_MARGIN * float(self._nominal("max_length"))
        inside: np.ndarray = q[self._lengths(q) < reach][: self.settings.n_candidates]
        return inside

    def design_dataset(self, q: np.ndarray) -> Dataset:
        """Nominal cable lengths at q (N, n) with the averaged reading's noise."""
        sigma = float(self._nominal("sigma")) / math.sqrt(AVERAGE)
        return self.samples_dataset([CableLength(floats(q[k]), float(length), sigma)
                                     for k, length in enumerate(self._lengths(q))])

    async def acquire(self, robot: RobotAdapter, phase: Phase, index: int, q: np.ndarray,
                      q_from: np.ndarray | None) -> SampleRecord:
        outcome = await move_or_skip(robot, self.settings.speed, phase, index, q, q_from)
        if isinstance(outcome, SampleRecord):
            return outcome
        reading = await sensors_of(robot, f"--method {self.name}").read_sensor(
            SENSOR, {"what": "length", "average": AVERAGE})
        if reading.reading.get("over_range"):
            return SampleRecord(phase, index, False, reason="cable over range",
                                q_end=outcome.q.tolist())
        sample = CableLength(floats(reading.q), float(reading.reading["length"]),
                             float(reading.reading["sigma"]))
        return SampleRecord.measured(phase, index, sample, q_end=outcome.q.tolist())

    def dataset(self, samples: Sequence[Mapping[str, Any]]) -> Dataset:
        """The journaled samples (their JSON form) as the run's Dataset."""
        return self.samples_dataset([CableLength.from_json(s) for s in samples])

    def samples_dataset(self, typed: Sequence[CableLength]) -> Dataset:
        """A Dataset of typed samples with the instrument's nominal frames."""
        fields = {"length": np.array([s.length for s in typed]),
                  "sigma": np.array([s.sigma for s in typed])}
        return Dataset(method=self.name, robot=RobotDescription(name=self.cell.robot),
                       frames={name: self._nominal(name) for name in FRAMES},
                       samples=Samples(q=np.array([s.q for s in typed]), fields=fields),
                       known=tuple(k for k in self.cell.known if k in FRAMES))

    def dataset_document(self, samples: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
        return dataset_to_dict(self.dataset(samples), plugins=self.settings.plugins)

    def describe(self) -> dict[str, Any]:
        return {"known": list(self.cell.known), "instrument": self._description}
