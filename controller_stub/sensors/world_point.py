"""A simulated laser tracker: reflectors (SMRs) on the flange, measured in the tracker's frame.

The tracker stands in the cell; its own frame is the `world` frame of the world_point
method. It measures each reflector's centre in spherical coordinates (distance by its
absolute distance meter, azimuth and elevation by its angle encoders), so its noise is
anisotropic: ``sigma_distance`` (m) along the line of sight and ``sigma_angle`` (rad) times
the distance across it. A reflector accepts the beam only inside a cone about its opening
axis (``acceptance_deg`` half-angle): past it the tracker loses the beam and reports the
reflector as lost. Robot self-occlusion is not modelled.

Truth: ``T_world_base`` (where the robot base really is in the tracker frame) and each
reflector's true position in the flange are the nominal values plus the scenario's errors;
the tracker software reports only the nominal ones (its registration and the nest
positions), as a real tracker's job file would. Everything random comes from the
simulation's seed.

Shapes: a flange pose is ``(4, 4)`` (base frame); points ``(3,)`` m; covariances
``(3, 3)`` m^2. Never imports hostpc.
"""

from __future__ import annotations

import math
from typing import Any, Protocol

import numpy as np

from controller_stub.geometry import make_transform, matrix_to_rpy
from controller_stub.scenario.tracker import TrackerSpec

__all__ = ["STREAM_TRACKER", "TrackedArm", "Tracker", "spherical_noise"]


def spherical_noise(p_world: np.ndarray, sigma_distance: float, sigma_angle: float
                    ) -> np.ndarray:
    """(3, 3) covariance of a point ``p_world`` (3,) measured by distance + two angles: the
    radial variance ``sigma_distance^2`` and the transverse ``(r sigma_angle)^2``."""
    r = float(np.linalg.norm(p_world))
    u = p_world / max(r, 1e-9)
    radial = np.outer(u, u)
    cov: np.ndarray = sigma_distance**2 * radial + (r * sigma_angle) ** 2 * (np.eye(3) - radial)
    return cov


class TrackedArm(Protocol):
    """What the tracker reads of the robot it measures (the arm `Simulation`)."""

    @property
    def time(self) -> float: ...
    def flange_pose(self) -> np.ndarray: ...
    def joint_positions(self) -> np.ndarray: ...
    def settle_for_measurement(self) -> float:
        """Settle before a measurement if the robot moved (the clock waits; s waited)."""
    def hold_for_capture(self) -> None:
        """Stand still for one measurement (the clock advances by `motion.capture_s`)."""


class Tracker:
    """The tracker of one simulation (see the module docstring).

    spec: the scenario's `tracker` section; rng: its noise stream; arm: the robot whose
    flange it measures in `measure_tracker` (None: only `measure` of a given pose).
    """

    def __init__(self, spec: TrackerSpec, rng: np.random.Generator,
                 arm: TrackedArm | None = None) -> None:
        self.spec = spec
        self.rng = rng
        self.arm = arm
        self.T_world_base_nominal = make_transform(spec.world_base.xyz, spec.world_base.rpy)
        self.T_world_base = self.T_world_base_nominal @ make_transform(
            spec.world_base_error.xyz, spec.world_base_error.rpy)
        self.cos_acceptance = math.cos(math.radians(spec.acceptance_deg))

    def reflector_true(self, name: str) -> np.ndarray:
        """(3,) the real reflector centre in the flange frame (m)."""
        r = self.spec.reflectors[name]
        position: np.ndarray = np.asarray(r.position, float) + np.asarray(r.error, float)
        return position

    def measure(self, T_base_flange: np.ndarray) -> tuple[dict[str, dict[str, Any]], list[str]]:
        """Measure every reflector at the true flange pose ``T_base_flange`` (4, 4).

        Returns ``(seen, lost)``: name -> {"p": (3,) m, "cov": (3, 3) m^2} in the tracker
        frame, and the names of reflectors whose beam is lost (outside their cone)."""
        T_world_flange = self.T_world_base @ T_base_flange
        seen: dict[str, dict[str, Any]] = {}
        lost: list[str] = []
        for name, spec in self.spec.reflectors.items():
            p = T_world_flange[:3, :3] @ self.reflector_true(name) + T_world_flange[:3, 3]
            axis = T_world_flange[:3, :3] @ np.asarray(spec.axis, float)
            axis /= np.linalg.norm(axis)
            to_tracker = -p / max(float(np.linalg.norm(p)), 1e-9)
            if float(axis @ to_tracker) < self.cos_acceptance:
                lost.append(name)
                continue
            seen[name] = self._noisy(p)
        return seen, lost

    def measure_tracker(self) -> dict[str, Any]:
        """Measure every reflector at the arm's current pose: {"q": (n,) reported, "time": s,
        "seen": name -> {"p", "cov"}, "lost": [names], "description": the tracker's nominal
        facts}."""
        if self.arm is None:
            raise RuntimeError("this tracker measures no robot (constructed without `arm`)")
        self.arm.settle_for_measurement()  # the flange stands still before it is measured
        seen, lost = self.measure(self.arm.flange_pose())
        measured = {"q": self.arm.joint_positions(), "time": float(self.arm.time),
                    "seen": seen, "lost": lost, "description": self.description()}
        self.arm.hold_for_capture()  # a reading takes robot time, as a stereo capture does
        return measured

    def _noisy(self, p: np.ndarray) -> dict[str, Any]:
        r = float(np.linalg.norm(p))
        azimuth = math.atan2(p[1], p[0])
        elevation = math.asin(p[2] / r)
        r += self.rng.normal(0.0, self.spec.sigma_distance)
        azimuth += self.rng.normal(0.0, self.spec.sigma_angle)
        elevation += self.rng.normal(0.0, self.spec.sigma_angle)
        measured = r * np.array([math.cos(elevation) * math.cos(azimuth),
                                 math.cos(elevation) * math.sin(azimuth),
                                 math.sin(elevation)])
        return {"p": measured,
                "cov": spherical_noise(measured, self.spec.sigma_distance,
                                       self.spec.sigma_angle)}

    def description(self) -> dict[str, Any]:
        """What the tracker software reports: the nominal registration and nest positions,
        the reflector axes, the acceptance cone and the noise model (never the truth)."""
        spec = self.spec
        return {
            "world_base": {"xyz": list(spec.world_base.xyz), "rpy": list(spec.world_base.rpy)},
            "reflectors": {n: list(r.position) for n, r in spec.reflectors.items()},
            "axes": {n: list(r.axis) for n, r in spec.reflectors.items()},
            "acceptance_deg": spec.acceptance_deg,
            "sigma_distance": spec.sigma_distance,
            "sigma_angle": spec.sigma_angle,
        }

    def truth(self) -> dict[str, Any]:
        """The hidden truth (for --truth-out and tests)."""
        return {
            "T_world_base": {"xyz": self.T_world_base[:3, 3].tolist(),
                             "rpy": matrix_to_rpy(self.T_world_base[:3, :3]).tolist()},
            "reflectors": {n: self.reflector_true(n).tolist() for n in self.spec.reflectors},
        }


STREAM_TRACKER = 7101
"""Random stream of the tracker's noise (distinct from the other streams' ids)."""
