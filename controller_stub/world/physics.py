"""Hidden physics: from the angles a controller reports to the physical joint angles.

    q_phys = q_reported + zero_error + encoder_scale * q_reported
             + harmonic(q_reported) + backlash * approach + compliance * tau(q_phys)

- `zero_error` (n,) rad is the CURRENT zero error: the scenario's zero error at the initial
  controller offsets, minus whatever the controller offsets have moved since
  (`Simulation` passes it in; see simulation.py).
- encoder_scale and the transmission harmonic act on the reported angle (the host's model,
  docs/conventions.md, writes them as functions of q_cmd).
- backlash: `approach_i` is +1 if joint i last moved in the positive direction, -1 if
  negative (the REAL direction of the last motion of that joint).
- compliance: tau is the ACTUAL gravity torque at the physical pose (including link-length
  errors and drift), solved by fixed-point iteration.
- link lengths: `delta_d(t) = link_length_errors.d + thermal_drift.d * t` and likewise for
  `a` (m), t the simulated run time (s).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from controller_stub.scenario.spec import TruthSpec
from controller_stub.world.robot_model import RobotModel, forward, gravity_torque

_COMPLIANCE_TOL = 1e-14  # rad
_COMPLIANCE_MAX_ITER = 60


@dataclass(frozen=True)
class HiddenEffects:
    """Magnitudes of the hidden effects, all (n,) except harmonic (n, 4); zeros when off."""

    joint_compliance: np.ndarray
    backlash: np.ndarray
    transmission_harmonic: np.ndarray
    encoder_scale: np.ndarray
    link_d: np.ndarray
    link_a: np.ndarray
    drift_d: np.ndarray
    drift_a: np.ndarray
    probe_trigger_latency_s: float

    @classmethod
    def from_spec(cls, spec: TruthSpec, n: int) -> HiddenEffects:
        """Build from the scenario's truth block (missing effects -> zeros)."""

        def vec(values: list[float] | None) -> np.ndarray:
            return np.zeros(n) if values is None else np.asarray(values, dtype=float)

        links, drift = spec.link_length_errors, spec.thermal_drift
        harmonic = (
            np.zeros((n, 4))
            if spec.transmission_harmonic is None
            else np.asarray(spec.transmission_harmonic, dtype=float)
        )
        return cls(
            joint_compliance=vec(spec.joint_compliance),
            backlash=vec(spec.backlash),
            transmission_harmonic=harmonic,
            encoder_scale=vec(spec.encoder_scale),
            link_d=vec(links.d if links else None),
            link_a=vec(links.a if links else None),
            drift_d=vec(drift.d if drift else None),
            drift_a=vec(drift.a if drift else None),
            probe_trigger_latency_s=float(spec.probe_trigger_latency_s),
        )

    def as_dict(self) -> dict[str, object]:
        """JSON-serialisable description (only the effects that are switched on)."""
        out: dict[str, object] = {}
        for name in ("joint_compliance", "backlash", "encoder_scale"):
            value = getattr(self, name)
            if np.any(value != 0):
                out[name] = value.tolist()
        if np.any(self.transmission_harmonic != 0):
            out["transmission_harmonic"] = self.transmission_harmonic.tolist()
        if np.any(self.link_d != 0) or np.any(self.link_a != 0):
            out["link_length_errors"] = {"d": self.link_d.tolist(), "a": self.link_a.tolist()}
        if np.any(self.drift_d != 0) or np.any(self.drift_a != 0):
            out["thermal_drift"] = {"d": self.drift_d.tolist(), "a": self.drift_a.tolist()}
        if self.probe_trigger_latency_s:
            out["probe_trigger_latency_s"] = self.probe_trigger_latency_s
        return out


class Physics:
    """Physical joint angles and link geometry of one simulated robot (stateless)."""

    def __init__(self, model: RobotModel, effects: HiddenEffects) -> None:
        self.model = model
        self.effects = effects

    def length_deltas(self, time_s: float) -> tuple[np.ndarray, np.ndarray]:
        """(delta_d (n,), delta_a (n,)) in m at simulated time `time_s`."""
        e = self.effects
        return e.link_d + e.drift_d * time_s, e.link_a + e.drift_a * time_s

    def origins(self, time_s: float | np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The robot's fixed transforms at `time_s` (see RobotModel.origins).

        A scalar time gives ((n, 4, 4), (4, 4)); an array of N times gives per-pose
        ((N, n, 4, 4), (N, 4, 4)) (lengths are linear in time, so this is exact).
        """
        if np.ndim(time_s) == 0:
            delta_d, delta_a = self.length_deltas(float(time_s))
            return self.model.origins(delta_d, delta_a)
        e = self.effects
        O0, F0 = self.model.origins(e.link_d, e.link_a)
        O1, F1 = self.model.origins(e.link_d + e.drift_d, e.link_a + e.drift_a)
        t = np.asarray(time_s, dtype=float)
        return (
            O0[None] + t[:, None, None, None] * (O1 - O0)[None],
            F0[None] + t[:, None, None] * (F1 - F0)[None],
        )

    @property
    def drifting(self) -> bool:
        """True if thermal drift is on (link lengths change with time)."""
        return bool(np.any(self.effects.drift_d) or np.any(self.effects.drift_a))

    def kinematic_angles(
        self, q_reported: np.ndarray, zero_error: np.ndarray, approach: np.ndarray
    ) -> np.ndarray:
        """All joint-space effects except compliance.

        q_reported: (N, n) rad; zero_error: (n,) rad; approach: (n,) or (N, n) of +-1.
        Returns (N, n) rad.
        """
        e = self.effects
        q = np.atleast_2d(np.asarray(q_reported, dtype=float))
        h = e.transmission_harmonic
        harmonic = (
            h[:, 0] * np.sin(q)
            + h[:, 1] * np.cos(q)
            + h[:, 2] * np.sin(2 * q)
            + h[:, 3] * np.cos(2 * q)
        )
        return q + zero_error + e.encoder_scale * q + harmonic + e.backlash * approach

    def physical_angles(
        self,
        q_reported: np.ndarray,
        zero_error: np.ndarray,
        approach: np.ndarray,
        time_s: float | np.ndarray,
    ) -> np.ndarray:
        """Physical joint angles (N, n) rad for reported angles (N, n) or (n,), at simulated
        time `time_s` (s, scalar or (N,)).

        Compliance is solved by fixed-point iteration q = q_kin + c * tau(q) (contraction
        for any realistic compliance).
        """
        q_kin = self.kinematic_angles(q_reported, zero_error, approach)
        c = self.effects.joint_compliance
        if not np.any(c != 0):
            return q_kin
        origins = self.origins(time_s)
        q = q_kin.copy()
        for _ in range(_COMPLIANCE_MAX_ITER):
            q_next = q_kin + c * gravity_torque(self.model, q, origins)
            step = float(np.max(np.abs(q_next - q)))
            q = q_next
            if step < _COMPLIANCE_TOL:
                break
        return q

    def flange_pose(self, q_phys: np.ndarray, time_s: float | np.ndarray) -> np.ndarray:
        """T_base_flange (N, 4, 4) at physical angles q_phys (N, n) and time `time_s` (s,
        scalar or (N,))."""
        _, T = forward(self.model, q_phys, self.origins(time_s))
        return T
