"""sphere_probe's sample as a typed value: one probe contact (SI).

A ``hostpc.methods.base.Sample``: built by the acquisition, journaled through ``to_json``,
read back with ``from_json``.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from hostpc.json_object import JsonObject
from hostpc.methods.base import floats, optional_json


@dataclass(frozen=True)
class ProbeSample:
    """q: (n,) joint angles (rad) latched at the contact; group: the probe orientation;
    sigma: the contact's position sigma (m) at its approach speed; approach: (n,) sign of
    each joint's motion into the contact; t: host time since the run's start (s);
    contact: the contact's number over the plan (group x contacts per orientation + its
    index in the group); speed: approach speed at contact (m/s; None: not known)."""

    q: tuple[float, ...]
    group: int
    sigma: float
    approach: tuple[float, ...]
    t: float
    contact: int
    speed: float | None = None

    def to_json(self) -> JsonObject:
        """The dataset-file form (one entry of ``samples``; the contact number and the tip
        speed in ``extra``)."""
        return {"q": list(self.q), "group": self.group, "sigma": self.sigma,
                "approach": list(self.approach), "t": self.t,
                "extra": {"contact": float(self.contact),
                          **optional_json(tip_speed=self.speed)},
                **optional_json(speed=self.speed)}

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> ProbeSample:
        """Inverse of ``to_json`` (a sample without a contact number gets -1)."""
        extra = data.get("extra") or {}
        return cls(q=floats(data["q"]), group=int(data["group"]),
                   sigma=float(data.get("sigma", 0.0)), approach=floats(data["approach"]),
                   t=float(data.get("t", 0.0)),
                   contact=int(round(float(extra.get("contact", -1)))),
                   speed=None if data.get("speed") is None else float(data["speed"]))
