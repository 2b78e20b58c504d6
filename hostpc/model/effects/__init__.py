"""Built-in physical effects. The registry (hostpc.model.registry) lists them by name."""

from hostpc.model.effects.coupling import JointCoupling
from hostpc.kinds.dual_loop.frames import DUAL_LOOP_FRAME_EFFECTS
from hostpc.model.effects.frames import BaseFrame, SphereFrame, TargetFrame, ToolFrame
from hostpc.model.effects.geometry import Geometry
from hostpc.model.effects.joint_space import (
    Backlash,
    EncoderScale,
    JointCompliance,
    JointOffsets,
    TransmissionHarmonic,
)
from hostpc.model.effects.sensor import DepthScale, TriggerLatency
from hostpc.model.effects.thermal import ThermalExpansion

BUILTIN_EFFECTS = (
    JointOffsets,
    ToolFrame,
    BaseFrame,
    TargetFrame,
    SphereFrame,
    Geometry,
    JointCompliance,
    EncoderScale,
    TransmissionHarmonic,
    Backlash,
    DepthScale,
    TriggerLatency,
    JointCoupling,
    ThermalExpansion,
    *DUAL_LOOP_FRAME_EFFECTS,
)

__all__ = [
    "Backlash",
    "BaseFrame",
    "DepthScale",
    "EncoderScale",
    "Geometry",
    "JointCompliance",
    "JointCoupling",
    "JointOffsets",
    "SphereFrame",
    "TargetFrame",
    "ThermalExpansion",
    "ToolFrame",
    "TransmissionHarmonic",
    "TriggerLatency",
    "BUILTIN_EFFECTS",
]
