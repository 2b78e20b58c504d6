"""The frame effect of sphere_probe's own frame, the reference sphere's centre (its math
lives in the measurement model, ``model.py``, which declares it in ``own_frame_effects``: the
effect registry lists it with the built-in effects). The dataset's value of that frame, centre
and radius, is ``hostpc.dataset.SphereFrame``."""

from __future__ import annotations

from hostpc.model.effects.frames import POINT_PARAMETERS, FrameEffect


class SphereCentreFrame(FrameEffect):
    """Reference sphere centre delta in the base frame (m); the radius is known."""

    name = "sphere"
    description = "reference sphere centre"
    parameters = POINT_PARAMETERS
