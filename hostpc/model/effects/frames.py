"""Frame effects: the unknown frames of a method. Their math lives in the measurement
models (hostpc.model.measurements); here they only declare their parameters. The frames every
serial kind shares (``tool``, ``base``) are here; a kind's own frames (stereo_target's
``target``, sphere_probe's ``sphere``, dual_loop's) are in its folder (``frames.py``,
declared by its model's ``own_frame_effects``)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import ClassVar

from hostpc.model.effect import Effect, Hook, ModelContext

POSE_PARAMETERS = ("x", "y", "z", "rx", "ry", "rz")
POINT_PARAMETERS = ("x", "y", "z")


class FrameEffect(Effect):
    hook: ClassVar[Hook] = "frame"
    parameters: ClassVar[tuple[str, ...]] = POSE_PARAMETERS

    def parameter_names(self, ctx: ModelContext) -> Sequence[str]:
        """The measurement model may say how its frame is parametrised (a point-only tool)."""
        return list(ctx.frame_parameters.get(self.name, self.parameters))

    def parameter_units(self, ctx: ModelContext) -> Sequence[str]:
        return ["rad" if name.rsplit(".", 1)[-1].startswith("r") else "m"
                for name in self.parameter_names(ctx)]


class ToolFrame(FrameEffect):
    """Sensor frame in the flange frame: T_flange_tool = T_nom @ [exp([r]x), t].

    For sphere_probe only the stylus tip position matters (x, y, z): its measurement model
    says so (``MeasurementModel.frame_parameters``)."""

    name = "tool"
    description = "sensor (camera or stylus tip) frame on the flange"


class BaseFrame(FrameEffect):
    """Robot base in the world frame where the target lives: T_world_base = T_nom @ delta."""

    name = "base"
    description = "robot base frame in the frame of the fixed target"


def frame_effect(name: str, parameters: tuple[str, ...]) -> type[FrameEffect]:
    """A frame effect class for a frame a measurement model declares that has no built-in
    effect of its own (a plugin's frame, world_point's markers)."""
    return type(f"Frame_{name}", (FrameEffect,), {
        "name": name, "parameters": parameters,
        "description": f"frame {name!r} of its measurement model"})
