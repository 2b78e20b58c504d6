"""Predicted measurements and their analytic Jacobians: ``predict(problem, x, jacobian)``
asks the problem's measurement model (``hostpc.model.measurements``). The shared pieces
(kinematic deltas, sensor effects) live in ``hostpc.model.measurements.terms``.
"""

from __future__ import annotations

import numpy as np

from hostpc.model.layout import Problem

__all__ = ["predict"]


def predict(problem: Problem, x: np.ndarray, jacobian: bool = True
            ) -> tuple[np.ndarray, np.ndarray | None]:
    """Predicted measurements (N, m) and their derivative by x (N, m, P) (or None)."""
    return problem.measurement.predict(problem, np.asarray(x, dtype=float), jacobian)
