"""Sensor effects: functions applied to the ideal sensor-frame measurement."""

from __future__ import annotations

from collections.abc import Sequence
from typing import ClassVar

import numpy as np

from hostpc.errors import EffectError
from hostpc.model.effect import Effect, Hook, ModelContext


class DepthScale(Effect):
    """Stereo depth scale: the coordinate along the optical axis (z) is scaled by 1 + s."""

    name = "depth_scale"
    hook: ClassVar[Hook] = "sensor"
    description = "stereo depth measured scaled by (1 + s) (baseline or focal length error)"
    methods = ()  # the stereo kinds name it (MeasurementModel.sensor_effects)
    advice = "Residuals grow with the distance along the camera's optical axis"

    def parameter_names(self, ctx: ModelContext) -> Sequence[str]:
        return ["s"]

    @classmethod
    def explains(cls, parameter: str, variable: str, ctx: ModelContext | None = None) -> bool:
        """The sensor frame's z moving with the depth."""
        return parameter == "tool.z" and variable == "depth"

    def sensor_apply(self, ctx: ModelContext, p: np.ndarray, y: np.ndarray) -> np.ndarray:
        out = y.copy()
        out[:, 2] = (1.0 + p[0]) * y[:, 2]
        return out

    def sensor_jacobians(
        self, ctx: ModelContext, p: np.ndarray, y: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        n_samples = y.shape[0]
        d_out_d_y = np.broadcast_to(np.diag([1.0, 1.0, 1.0 + p[0]]), (n_samples, 3, 3)).copy()
        d_out_d_p = np.zeros((n_samples, 3, 1))
        d_out_d_p[:, 2, 0] = y[:, 2]
        return d_out_d_y, d_out_d_p


class TriggerLatency(Effect):
    """Probe trigger latency: the joints are latched `latency` seconds after the contact, so
    at the latched angles the stylus is speed * latency deeper into the sphere. The contact
    distance R + r is therefore predicted as
    distance(latched q) + latency * speed (speed: approach speed along the contact normal,
    m/s), so a positive latency is a late latch."""

    name = "trigger_latency"
    hook: ClassVar[Hook] = "sensor"
    unit = "s"
    description = "joints latched late after the probe's contact: overtravel grows with speed"
    methods = ()  # the probe kind names it (MeasurementModel.sensor_effects)
    advice = "Residuals grow with the probe's approach speed"

    def parameter_names(self, ctx: ModelContext) -> Sequence[str]:
        return ["latency"]

    @classmethod
    def explains(cls, parameter: str, variable: str, ctx: ModelContext | None = None) -> bool:
        """Any parameter moving with the approach speed."""
        return variable == "speed"

    def _speed(self, ctx: ModelContext) -> np.ndarray:
        if "speed" not in ctx.variables:
            raise EffectError("trigger_latency needs the approach `speed` of every contact")
        return ctx.variables["speed"]

    def sensor_apply(self, ctx: ModelContext, p: np.ndarray, y: np.ndarray) -> np.ndarray:
        return y + p[0] * self._speed(ctx)[:, None]

    def sensor_jacobians(
        self, ctx: ModelContext, p: np.ndarray, y: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        n_samples = y.shape[0]
        return np.ones((n_samples, 1, 1)), self._speed(ctx).reshape(n_samples, 1, 1)
