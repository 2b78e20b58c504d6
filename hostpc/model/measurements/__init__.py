"""Measurement models: what an instrument sees, as plugins (see ``base``).

Built-ins: ``stereo_target``, ``sphere_probe``, ``dual_loop``. Add one by subclassing
``MeasurementModel`` in a plugin file (``--plugin FILE``) or publishing it under the
entry-point group ``zerocal.measurements``; docs/measurement-models.md has an example.
"""

from hostpc.model.measurements.base import POINT, POSE, MeasurementModel
from hostpc.model.measurements.registry import (
    BUILTIN_MODELS,
    measurement_model,
    measurement_models,
)

__all__ = ["BUILTIN_MODELS", "POINT", "POSE", "MeasurementModel", "measurement_model",
           "measurement_models"]
