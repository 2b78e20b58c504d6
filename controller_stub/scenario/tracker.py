"""The scenario's `tracker` section: the simulated laser tracker's registration, reflectors
and noise (the sensor itself is `controller_stub/sensors/world_point.py`).

Poses are xyz (m) and roll-pitch-yaw (rad); noise 1-sigma (m, rad).
"""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict, Field

__all__ = ["PoseSpec", "ReflectorSpec", "TrackerSpec"]


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class PoseSpec(_Model):
    """A pose as xyz (m) and roll-pitch-yaw (rad)."""

    xyz: list[float] = Field(default=[0.0, 0.0, 0.0], min_length=3, max_length=3)
    rpy: list[float] = Field(default=[0.0, 0.0, 0.0], min_length=3, max_length=3)


class ReflectorSpec(_Model):
    """One reflector: nominal centre in the flange frame (m), the error of the real one,
    and its opening axis in the flange frame."""

    position: list[float] = Field(min_length=3, max_length=3)
    error: list[float] = Field(default=[0.0, 0.0, 0.0], min_length=3, max_length=3)
    axis: list[float] = Field(default=[0.0, 0.0, 1.0], min_length=3, max_length=3)


class TrackerSpec(_Model):
    """The scenario's `tracker` section (defaults: a tracker 2.4 m from the base).

    world_base: nominal pose of the robot base in the tracker frame (the registration);
    world_base_error: the real base differs from it by this (applied on the right);
    reflectors: name -> reflector; sigma_distance (m), sigma_angle (rad): 1-sigma noise;
    acceptance_deg: half-angle of each reflector's acceptance cone."""

    world_base: PoseSpec = PoseSpec(xyz=[2.2, 0.9, -0.35], rpy=[0.0, 0.0, 2.7])
    world_base_error: PoseSpec = PoseSpec()
    reflectors: dict[str, ReflectorSpec] = Field(
        default_factory=lambda: {"smr1": ReflectorSpec(position=[0.03, -0.02, 0.06])})
    sigma_distance: float = Field(default=8e-6, ge=0.0)
    sigma_angle: float = Field(default=4e-6, ge=0.0)
    acceptance_deg: float = Field(default=55.0, gt=0.0, le=90.0)
