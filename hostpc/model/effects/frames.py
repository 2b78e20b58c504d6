"""Frame effects: the unknown frames of a method. Their math lives in the measurement
models (hostpc.model.measurement); here they only declare their parameters."""

from __future__ import annotations

from collections.abc import Sequence
from typing import ClassVar

from hostpc.model.effect import Effect, Hook, ModelContext

POSE_PARAMETERS = ("x", "y", "z", "rx", "ry", "rz")
POINT_PARAMETERS = ("x", "y", "z")


class _FrameEffect(Effect):
    hook: ClassVar[Hook] = "frame"
    parameters: ClassVar[tuple[str, ...]] = POSE_PARAMETERS

    def parameter_names(self, ctx: ModelContext) -> Sequence[str]:
        return list(self.parameters)

    def parameter_units(self, ctx: ModelContext) -> Sequence[str]:
        return ["rad" if name.startswith("r") else "m" for name in self.parameter_names(ctx)]


class ToolFrame(_FrameEffect):
    """Sensor frame in the flange frame: T_flange_tool = T_nom @ [exp([r]x), t].

    For sphere_probe only the stylus tip position matters (x, y, z)."""

    name = "tool"
    description = "sensor (camera or stylus tip) frame on the flange"

    def parameter_names(self, ctx: ModelContext) -> Sequence[str]:
        if ctx.method == "sphere_probe":
            return list(POINT_PARAMETERS)
        return list(POSE_PARAMETERS)


class BaseFrame(_FrameEffect):
    """Robot base in the world frame where the target lives: T_world_base = T_nom @ delta."""

    name = "base"
    description = "robot base frame in the frame of the fixed target"


class TargetFrame(_FrameEffect):
    """Target point delta in the base frame (m)."""

    name = "target"
    description = "fixed target point"
    parameters = POINT_PARAMETERS


class SphereFrame(_FrameEffect):
    """Reference sphere centre delta in the base frame (m); the radius is known."""

    name = "sphere"
    description = "reference sphere centre"
    parameters = POINT_PARAMETERS
