"""Built-in physical effects. The registry (hostpc.model.registry) lists them by name, with
the frame effects the built-in kinds declare for their own frames
(``MeasurementModel.own_frame_effects``)."""

from hostpc.model.effects.coupling import JointCoupling
from hostpc.model.effects.frames import BaseFrame, ToolFrame
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
    Geometry,
    JointCompliance,
    EncoderScale,
    TransmissionHarmonic,
    Backlash,
    DepthScale,
    TriggerLatency,
    JointCoupling,
    ThermalExpansion,
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
    "ThermalExpansion",
    "ToolFrame",
    "TransmissionHarmonic",
    "TriggerLatency",
    "BUILTIN_EFFECTS",
]
