"""The frame effect of stereo_target's own frame, the fixed target point (its math lives in
the measurement model, ``model.py``, which declares it in ``own_frame_effects``: the effect
registry lists it with the built-in effects)."""

from __future__ import annotations

from hostpc.model.effects.frames import POINT_PARAMETERS, FrameEffect


class TargetFrame(FrameEffect):
    """Target point delta in the base frame (m)."""

    name = "target"
    description = "fixed target point"
    parameters = POINT_PARAMETERS
