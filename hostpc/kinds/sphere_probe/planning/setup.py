"""sphere_probe set-up: what the cell is (``ProbeSetup``) and how to probe (``PlanConfig``).

Frozen values shared by planning (``sphere_planning``), acquisition
(``sphere_acquisition``), the dataset (``sphere_dataset``) and the method
(``sphere_probe``). Units SI (m, rad, s); frames per docs/conventions.md.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Final

import numpy as np

from hostpc.errors import InputError
from hostpc.json_object import JsonObject

METHOD: Final = "sphere_probe"
CONTACTS_PER_ORIENTATION = 5
MIN_ORIENTATIONS = 20
"""Probe orientations of a fixed-count plan (``--poses N`` alone; patent S6: >= 20)."""
MIN_TARGET_ORIENTATIONS = 2
"""The fewest probe orientations of a target-sigma plan (the default): 10 contacts for the
9 parameters of the default model with the sphere known (5 joint offsets, the tip, the
trigger latency); the target itself asks for 3 (docs/sphere-probe.md)."""


@dataclass(frozen=True)
class ProbeSetup:
    """What the cell is: nominal frames, sizes, the probe line and its noise.

    sphere_centre: (3,) nominal sphere centre in base (m); sphere_radius: R (m);
    stylus_radius: r (m); tip: (3,) nominal stylus tip centre in the flange frame (m);
    io_line: digital input of the probe; repeatability: one-sigma contact repeatability of
    the probe (m); latency_jitter: one-sigma jitter of the trigger-to-latch delay (s), which
    becomes a distance error of jitter * approach speed; known: frames trusted and held in
    the fit (``"sphere"`` for a sphere surveyed in the base frame, ``"tool"`` for a measured
    stylus).
    """

    sphere_centre: np.ndarray
    sphere_radius: float = 0.0125
    stylus_radius: float = 0.0015
    tip: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, 0.12]))
    io_line: int = 0
    repeatability: float = 1e-6
    latency_jitter: float = 1e-5
    known: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        object.__setattr__(self, "sphere_centre", np.asarray(self.sphere_centre, float))
        object.__setattr__(self, "tip", np.asarray(self.tip, float))
        object.__setattr__(self, "known", tuple(self.known))
        if self.sphere_radius <= 0 or self.stylus_radius < 0:
            raise InputError("sphere radius must be > 0 and stylus radius >= 0")
        if np.linalg.norm(self.tip) < 1e-6:
            raise InputError("the stylus tip must be away from the flange origin")
        for name in self.known:
            if name not in ("sphere", "tool"):
                raise InputError(f"known frame {name!r}: sphere_probe knows 'sphere', 'tool'")

    @property
    def contact_distance(self) -> float:
        """R + r (m): tip-centre to sphere-centre distance at contact."""
        return float(self.sphere_radius + self.stylus_radius)

    def contact_sigma(self, speed: np.ndarray | float) -> np.ndarray:
        """(N,) one-sigma contact distance error (m) at approach speeds (N,) m/s."""
        speed = np.nan_to_num(np.asarray(speed, float), nan=0.0)
        return np.sqrt(self.repeatability**2 + (self.latency_jitter * speed) ** 2)

    @classmethod
    def from_description(cls, description: JsonObject, **overrides: Any) -> ProbeSetup:
        """From a dict with keys sphere_centre, sphere_radius, stylus_radius, tip, io_line,
        repeatability, latency_jitter, known (SI); ``overrides`` win."""
        values = {k: v for k, v in description.items() if k in cls.__dataclass_fields__}
        values.update({k: v for k, v in overrides.items() if v is not None})
        if "sphere_centre" not in values:
            raise InputError("sphere_probe needs the nominal sphere centre (sphere_centre)")
        return cls(**values)


@dataclass(frozen=True)
class PlanConfig:
    """How to probe.

    n_orientations: probe orientations (>= 20, S6); max_tilt_deg: largest tilt of the stylus
    axis from straight down; ring_deg: angle of the 4 outer contacts from the pole contact
    (the 5th); max_normal_deg: contact normals stay within this of base +z (the sphere's
    post is below it); standoff: start pose distance from the surface (m); overtravel:
    target depth past the surface (m) (must exceed the nominal frames' error); hover: tip
    distance from the sphere centre between orientations (m); guarded_speeds: guarded-move
    speed fractions, cycled over contacts (a spread of approach speeds separates the
    trigger latency); move_speed: speed fraction of free moves; seed: candidate draw.
    """

    n_orientations: int = 24
    max_tilt_deg: float = 30.0
    ring_deg: float = 40.0
    max_normal_deg: float = 75.0
    standoff: float = 0.010
    overtravel: float = 0.012
    hover: float = 0.06
    guarded_speeds: tuple[float, ...] = (0.01, 0.02, 0.04)
    move_speed: float = 0.3
    seed: int = 0
