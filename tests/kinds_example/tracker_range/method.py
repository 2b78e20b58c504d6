"""tracker_range's acquisition: move, ``measure_tracker``, keep the reflector's distance.

Planning, the tracker's description and the approach moves are world_point's
(``WorldPointMethod``, the same instrument); what differs is the sample (a distance and
its sigma, the tracker's ``sigma_distance``) and the frames: the reflector in the flange
(``tool``) and the tracker's origin in the robot base frame (``anchor``, from the
registration ``world``).
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from typing import Any, ClassVar

import numpy as np

from hostpc.dataset import FORMAT_TAG, Dataset, dataset_from_dict
from hostpc.files import write_json_atomic
from hostpc.kinds.world_point.method import WorldPointMethod
from hostpc.kinematics import forward, pose_to_transform
from hostpc.methods.base import Phase, Progress, SampleRecord
from hostpc.robots.base import RobotAdapter, tracker_of


class TrackerRangeMethod(WorldPointMethod):
    """See the module docstring."""

    name: ClassVar[str] = "tracker_range"

    async def prepare(self, robot: RobotAdapter, progress: Progress) -> None:
        """Read the tracker's description (kept in the run folder for a resume)."""
        if self.tracker_path.is_file():
            self._description = json.loads(self.tracker_path.read_text(encoding="utf-8"))
        else:
            reading = await tracker_of(robot, f"--method {self.name}").measure_tracker()
            self._description = dict(reading.description)
            write_json_atomic(self.tracker_path, self._description)

    def _reflector(self) -> tuple[str, list[float]]:
        name, xyz = next(iter(self.markers().items()))
        return name, xyz

    def _anchor(self) -> list[float]:
        """The tracker's origin in the robot base frame (m)."""
        world = self.world()
        T_world_base = pose_to_transform(world["xyz"], world["rpy"])
        R, t = T_world_base[:3, :3], T_world_base[:3, 3]
        return [float(v) for v in -R.T @ t]

    def design_dataset(self, q: np.ndarray) -> Dataset:
        """Nominal distances at q (N, n) with the tracker's distance noise."""
        tool = np.asarray(self._reflector()[1])
        T = forward(self._chain, q).T_base_flange
        tip = np.einsum("nij,j->ni", T[:, :3, :3], tool) + T[:, :3, 3]
        distance = np.linalg.norm(tip - np.asarray(self._anchor()), axis=1)
        sigma = self._noise()[0]
        return dataset_from_dict(self.dataset_document(
            [{"q": q[k].tolist(), "distance": float(distance[k]), "sigma": sigma,
              "t": float(k)} for k in range(q.shape[0])]), plugins=self.settings.plugins)

    async def acquire(self, robot: RobotAdapter, phase: Phase, index: int, q: np.ndarray,
                      q_from: np.ndarray | None) -> SampleRecord:
        outcome = await self._moves.move(robot, phase, index, q, q_from)
        if isinstance(outcome, SampleRecord):
            return outcome
        reading = await tracker_of(robot, f"--method {self.name}").measure_tracker()
        name = self._reflector()[0]
        if name not in reading.points:
            return SampleRecord(phase, index, False, reason=f"beam lost: {name}",
                                q_end=outcome.q.tolist())
        p, _ = reading.points[name]
        sample = {"q": [float(v) for v in reading.q],
                  "distance": float(np.linalg.norm(np.asarray(p, float))),
                  "sigma": self._noise()[0], "t": float(reading.time) - self._t0,
                  "approach": self._moves.signs(q_from, reading.q)}
        return SampleRecord(phase, index, True, sample=sample, q_end=outcome.q.tolist())

    def dataset_document(self, samples: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
        return {
            "format": FORMAT_TAG, "method": self.name,
            "units": {"length": "m", "angle": "rad", "time": "s"},
            "robot": {"name": self.cell.robot},
            "frames": {"tool": self._reflector()[1], "anchor": self._anchor()},
            "known": [k for k in self.cell.known if k in ("tool", "anchor")],
            "samples": [dict(s) for s in samples],
        }

    def describe(self) -> dict[str, Any]:
        return {"known": list(self.cell.known)}
