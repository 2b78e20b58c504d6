"""Frame effects of the dual_loop method (a head camera observing targets on two arms).

Their math lives in the measurement model (``hostpc.kinds.dual_loop.model``), which declares
them (``own_frame_effects``: the effect registry lists them with the built-in effects); here
they only declare their parameters. Pose deltas follow conventions.md:
``T = T_nom @ [exp([r]x), t]`` (translation delta in the parent frame, m; rotation vector
in the frame itself, rad).
"""

from __future__ import annotations

from hostpc.model.effects.frames import POINT_PARAMETERS, FrameEffect


class CameraFrame(FrameEffect):
    """Stereo camera (left optical) frame in the head chain's end frame: T_end_camera."""

    name = "camera"
    description = "stereo camera frame on the pan-tilt head (dual_loop)"


class LeftBaseFrame(FrameEffect):
    """Left arm base in the head chain's base frame: T_headbase_leftbase."""

    name = "left_base"
    description = "left arm base relative to the pan-tilt base (dual_loop)"


class RightBaseFrame(FrameEffect):
    """Right arm base in the head chain's base frame: T_headbase_rightbase."""

    name = "right_base"
    description = "right arm base relative to the pan-tilt base (dual_loop)"


class LeftTargetFrame(FrameEffect):
    """Left target point delta in the left flange frame (m)."""

    name = "left_target"
    description = "target point on the left flange (dual_loop)"
    parameters = POINT_PARAMETERS


class RightTargetFrame(FrameEffect):
    """Right target point delta in the right flange frame (m)."""

    name = "right_target"
    description = "target point on the right flange (dual_loop)"
    parameters = POINT_PARAMETERS


DUAL_LOOP_FRAME_EFFECTS = (CameraFrame, LeftBaseFrame, RightBaseFrame, LeftTargetFrame,
                           RightTargetFrame)
