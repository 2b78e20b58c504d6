"""dual_loop's samples as typed values: one target observation, and one pose's observations.

The acquisition builds a ``PoseObservations`` per pose; the journal stores it through
``to_json`` (``{"observations": [...]}``, each observation in dataset-file form, key for key
as the journal has always held it, so an old run resumes) and the dataset is built from the
observations read back with ``from_json``.
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
    optional_matrix,
    optional_rows,
    optional_stack,
    optional_values,
)


@dataclass(frozen=True)
class TargetObservation:
    """chain: the arm whose target was seen ("left" / "right"); q_head, q_arm: the head's
    and that arm's joint angles (rad); p: (3,) the target in the camera frame (m); cov:
    (3, 3) its covariance (m^2); t: s since the run's start; approach: the arm's joints'
    last motion signs (None: unknown); uv: (2, 2) the target's centres in the left and
    right images (px; None: not reported)."""

    chain: str
    q_head: tuple[float, ...]
    q_arm: tuple[float, ...]
    p: tuple[float, ...]
    cov: tuple[tuple[float, ...], ...]
    t: float
    approach: tuple[float, ...] | None = None
    uv: tuple[tuple[float, ...], ...] | None = None

    def to_json(self) -> JsonObject:
        """The dataset-file form (one entry of ``samples``)."""
        return {"chain": self.chain, "q_head": list(self.q_head), "q_arm": list(self.q_arm),
                "p": list(self.p), "cov": [list(row) for row in self.cov], "t": self.t,
                **optional_json(approach=self.approach, uv=self.uv)}

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> TargetObservation:
        """Inverse of ``to_json``."""
        return cls(chain=str(data["chain"]), q_head=floats(data["q_head"]),
                   q_arm=floats(data["q_arm"]), p=floats(data["p"]),
                   cov=matrix(data["cov"]), t=float(data.get("t", 0.0)),
                   approach=optional_floats(data, "approach"), uv=optional_matrix(data, "uv"))


@dataclass(frozen=True)
class PoseObservations:
    """One pose's sample: the observation of each arm whose target was in view."""

    observations: tuple[TargetObservation, ...]

    def to_json(self) -> JsonObject:
        """The journal's form: ``{"observations": [...]}``."""
        return {"observations": [o.to_json() for o in self.observations]}

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> PoseObservations:
        """Inverse of ``to_json``; a plain observation (a sample of a dataset document) is
        a pose with that one observation."""
        if "observations" in data:
            return cls(tuple(TargetObservation.from_json(o) for o in data["observations"]))
        return cls((TargetObservation.from_json(data),))


def observation_samples(observations: Sequence[TargetObservation]) -> Samples:
    """The observations as a dataset's ``Samples``: ``q`` the observed arm's joints,
    NaN-padded to the longer arm; ``uv`` NaN where an observation has none."""
    n = len(observations)
    width = max((len(o.q_arm) for o in observations), default=0)
    return Samples(
        q=optional_rows([o.q_arm for o in observations], width),
        p=np.array([o.p for o in observations], dtype=float).reshape(n, 3),
        cov=np.array([o.cov for o in observations], dtype=float).reshape(n, 3, 3),
        t=optional_values([o.t for o in observations]),
        approach=optional_rows([o.approach for o in observations], width),
        uv=optional_stack([o.uv for o in observations], (2, 2)),
        chain=np.asarray([o.chain for o in observations], dtype=np.str_),
        q_head=np.array([o.q_head for o in observations], dtype=float))
