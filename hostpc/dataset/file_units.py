"""Unit conversion of a ``zerocal-dataset/1`` file's numbers to SI (m, rad, s).

The file states its units (``units``: length m/mm, angle rad/deg, time s/ms); reading
converts every value through ``Units`` once, so everything after it is SI.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from hostpc.dataset import schema
from hostpc.dataset.model import FloatArray


class Units:
    """Conversion of the file's numbers to SI."""

    def __init__(self, units: schema.UnitsSchema) -> None:
        self.units = units

    def length(self, value: Any) -> FloatArray:
        """File length -> m."""
        array = np.asarray(value, dtype=np.float64)
        return array / 1000.0 if self.units.length == "mm" else array

    def area(self, value: Any) -> FloatArray:
        """File length^2 (a covariance) -> m^2."""
        return self.length(self.length(value))

    def angle(self, value: Any) -> FloatArray:
        """File angle -> rad."""
        array = np.asarray(value, dtype=np.float64)
        return np.deg2rad(array) if self.units.angle == "deg" else array

    def time(self, value: Any) -> FloatArray:
        """File time -> s."""
        array = np.asarray(value, dtype=np.float64)
        return array / 1000.0 if self.units.time == "ms" else array

    def speed(self, value: Any) -> FloatArray:
        """File length/time -> m/s."""
        array = self.length(value)
        return array * 1000.0 if self.units.time == "ms" else array
