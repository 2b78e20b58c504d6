"""string_pot's instrument as the simulated controller serves it (``sensor_read``).

Loaded by the stub alone (``controller-stub serve --sensor-plugin FOLDER``), so it imports
numpy and controller_stub only, never hostpc: the simulator's truth must not share code
with the fitter (controller_stub/sensors/registry.py).

The drum sits at ``anchor`` (robot base frame, m), the hook at ``tool`` (flange frame, m);
their real positions are those plus ``anchor_error`` / ``tool_error`` (the scenario's
``sensors.string_pot`` section; the description reports the nominal ones, as a data sheet
would). One reading is the true cable length plus Gaussian noise ``sigma`` (m); a request
may average ``average`` readings. Past ``max_length`` the cable is at its end stop and the
reading says ``over_range``.

Requests (the contract with ``method.py``)::

    {"what": "describe"}                 -> {"anchor", "tool", "sigma", "max_length"}
    {"what": "length", "average": N}     -> {"length": m, "sigma": m} | {"over_range": true}
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from controller_stub.sensors.registry import SensorRequestError, SensorSetup

MAX_AVERAGE = 64


def _vector(settings: Mapping[str, Any], key: str, default: list[float]) -> np.ndarray:
    value = np.asarray(settings.get(key, default), dtype=float)
    if value.shape != (3,) or not np.all(np.isfinite(value)):
        raise ValueError(f"sensors.string_pot.{key}: expected 3 finite numbers (m)")
    return value


class SimulatedStringPot:
    """The draw-wire sensor of one simulation (see the module docstring)."""

    def __init__(self, setup: SensorSetup) -> None:
        s = setup.settings
        self.world = setup.world
        self.rng = setup.rng
        self.anchor = _vector(s, "anchor", [0.55, 0.45, -0.15])
        self.tool = _vector(s, "tool", [0.0, 0.04, 0.05])
        self.anchor_true = self.anchor + _vector(s, "anchor_error", [0.0, 0.0, 0.0])
        self.tool_true = self.tool + _vector(s, "tool_error", [0.0, 0.0, 0.0])
        self.sigma = float(s.get("sigma", 2e-5))
        self.max_length = float(s.get("max_length", 2.0))

    def read(self, request: Mapping[str, Any]) -> dict[str, Any]:
        what = request.get("what")
        if what == "describe":
            return {"anchor": self.anchor.tolist(), "tool": self.tool.tolist(),
                    "sigma": self.sigma, "max_length": self.max_length}
        if what != "length":
            raise SensorRequestError(f"'what' is {what!r}, not 'describe' or 'length'")
        average = request.get("average", 1)
        if type(average) is not int or not 1 <= average <= MAX_AVERAGE:
            raise SensorRequestError(f"'average' is {average!r}, not an integer 1..{MAX_AVERAGE}")
        T = self.world.flange_pose()
        length = float(np.linalg.norm(T[:3, :3] @ self.tool_true + T[:3, 3] - self.anchor_true))
        if length > self.max_length:
            return {"over_range": True}
        noise = self.rng.normal(0.0, self.sigma, average).mean()
        sigma = self.sigma / np.sqrt(average)
        return {"length": length + float(noise), "sigma": float(sigma)}

    def truth(self) -> dict[str, Any]:
        return {"anchor": self.anchor_true.tolist(), "tool": self.tool_true.tolist()}


SIM_SENSORS = {"string_pot": SimulatedStringPot}
