"""Measurement models: what an instrument sees, as plugins (see ``base``).

The built-in ones live with the rest of their kind in ``hostpc/kinds/<name>/model.py``;
``registry`` finds them, and a plugin's, through the one kind registry
(``hostpc.dataset.kind_registry``). Add one by subclassing ``MeasurementModel`` in a plugin
file (``--plugin FILE``) or publishing it under the entry-point group
``zerocal.measurements``; docs/measurement-models.md has an example.
"""

from hostpc.model.measurements.base import POINT, POSE, MeasurementModel
from hostpc.model.measurements.registry import measurement_model, measurement_models

__all__ = ["POINT", "POSE", "MeasurementModel", "measurement_model", "measurement_models"]
