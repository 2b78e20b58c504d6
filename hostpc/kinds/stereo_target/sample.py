"""stereo_target's sample as a typed value: what one pose's capture measured (SI).

The acquisition builds it; the journal stores it through ``to_json`` (the sample's
dataset-file form, key for key as the journal has always held it, so an old run resumes)
and the dataset is read back from that form with ``from_json``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from hostpc.dataset.model import Samples
from hostpc.json_object import JsonObject
from hostpc.methods.base import (
    floats,
    matrix,
    optional_floats,
    optional_json,
    optional_matrix,
    optional_stack,
    point_samples,
)


@dataclass(frozen=True)
class StereoSample:
    """q: (n,) joint angles (rad) at the capture; p: (3,) target point in the sensor frame
    (m); cov: (3, 3) its covariance (m^2); t: s since the run's start (None: untimed);
    approach: (n,) sign of each joint's last motion (None: unknown); uv: (2, 2) the disk
    centres in the left and right images (px; None: not reported)."""

    q: tuple[float, ...]
    p: tuple[float, ...]
    cov: tuple[tuple[float, ...], ...]
    t: float | None = None
    approach: tuple[float, ...] | None = None
    uv: tuple[tuple[float, ...], ...] | None = None

    def to_json(self) -> JsonObject:
        """The dataset-file form (one entry of ``samples``)."""
        return {"q": list(self.q), "p": list(self.p), "cov": [list(row) for row in self.cov],
                **optional_json(t=self.t, approach=self.approach, uv=self.uv)}

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> StereoSample:
        """Inverse of ``to_json``."""
        return cls(q=floats(data["q"]), p=floats(data["p"]), cov=matrix(data["cov"]),
                   t=None if data.get("t") is None else float(data["t"]),
                   approach=optional_floats(data, "approach"),
                   uv=optional_matrix(data, "uv"))


def stereo_samples(samples: Sequence[StereoSample], n_joints: int) -> Samples:
    """The samples as a dataset's ``Samples`` (``uv`` NaN where a sample has none)."""
    return point_samples(samples, n_joints,
                         uv=optional_stack([s.uv for s in samples], (2, 2)))

