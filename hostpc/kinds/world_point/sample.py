"""world_point's sample as a typed value: one tracker reading of a flange reflector (SI).

A ``hostpc.methods.base.Sample``: built by the acquisition, journaled through ``to_json``,
read back with ``from_json``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from hostpc.dataset.model import Samples
from hostpc.json_object import JsonObject
from hostpc.methods.base import (
    floats,
    matrix,
    optional_floats,
    optional_json,
    point_samples,
)


@dataclass(frozen=True)
class WorldPointSample:
    """q: (n,) joint angles (rad) at the reading; marker: the reflector's name
    (``frames.markers``); p: (3,) its position in the world frame (m); cov: (3, 3) its
    covariance (m^2); t: s since the run's start (None: untimed); approach: (n,) sign of
    each joint's last motion (None: unknown)."""

    q: tuple[float, ...]
    marker: str
    p: tuple[float, ...]
    cov: tuple[tuple[float, ...], ...]
    t: float | None = None
    approach: tuple[float, ...] | None = None

    def to_json(self) -> JsonObject:
        """The dataset-file form (one entry of ``samples``)."""
        return {"q": list(self.q), "marker": self.marker, "p": list(self.p),
                "cov": [list(row) for row in self.cov],
                **optional_json(t=self.t, approach=self.approach)}

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> WorldPointSample:
        """Inverse of ``to_json``."""
        return cls(q=floats(data["q"]), marker=str(data["marker"]), p=floats(data["p"]),
                   cov=matrix(data["cov"]),
                   t=None if data.get("t") is None else float(data["t"]),
                   approach=optional_floats(data, "approach"))


def world_point_samples(samples: Sequence[WorldPointSample], n_joints: int) -> Samples:
    """The samples as a dataset's ``Samples`` (every axis measured: ``mask`` all ones)."""
    return point_samples(
        samples, n_joints,
        fields={"marker": np.asarray([s.marker for s in samples], dtype=np.str_),
                "mask": np.ones((len(samples), 3))})
