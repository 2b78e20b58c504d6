"""The host zero offsets of the UR driver: validated, replaced with a rollback id, exported.

Part of `hostpc.robots.ur.UrAdapter` (a mixin; the adapter provides the host name and the
angle check). A UR controller offers no way to write joint zero offsets, so the adapter
applies them on the host (`ur.py`'s module docstring: command = wanted - o, reported =
measured + o); nothing here writes to the robot. `export_offsets` writes them for the
software that drives the robot (`hostpc.robots.ur_export`). Angles rad.
"""

from __future__ import annotations

import logging
import math
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from hostpc.errors import ControllerError

logger = logging.getLogger("hostpc.robots.ur")

MAX_OFFSET_RAD = math.radians(5.0)
"""Largest host zero offset accepted by set_offsets (a bigger one is a fitting error)."""


class UrOffsetsMixin:
    """get_offsets / set_offsets / rollback / export_offsets of `UrAdapter`."""

    host: str
    EXPORT_STEM: str
    _offsets: np.ndarray
    _rollbacks: dict[str, np.ndarray]
    _rollback_counter: int

    if TYPE_CHECKING:  # provided by UrAdapter

        def _check_q(self, q: np.ndarray | list[float], name: str = "q") -> np.ndarray: ...

    def _check_offsets(self, offsets: np.ndarray | list[float]) -> np.ndarray:
        values = self._check_q(offsets, "offsets")
        if np.any(np.abs(values) > MAX_OFFSET_RAD):
            i = int(np.argmax(np.abs(values)))
            raise ControllerError(
                f"UR host offsets: joint {i + 1} offset {math.degrees(values[i]):.3f} deg "
                f"exceeds the limit {math.degrees(MAX_OFFSET_RAD):.1f} deg"
            )
        return values

    async def get_offsets(self) -> np.ndarray:
        """The host zero offsets (6,) rad (the UR's own calibration is not readable)."""
        return self._offsets.copy()

    async def set_offsets(self, offsets: np.ndarray) -> tuple[np.ndarray, str]:
        """Replace the host zero offsets (nothing is written to the robot); returns
        (previous offsets, rollback id)."""
        new = self._check_offsets(offsets)
        previous = self._offsets.copy()
        self._rollback_counter += 1
        rollback_id = f"ur-host-{self._rollback_counter}"
        self._rollbacks[rollback_id] = previous
        self._offsets = new
        logger.info("UR %s: host zero offsets set to %s (robot unchanged)", self.host, new)
        return previous, rollback_id

    def export_offsets(self, directory: str | Path, robot: str,
                       offsets: np.ndarray) -> dict[str, Path]:
        """Write `offsets` (6,) rad of robot model `robot` (e.g. `ur5e`) into `directory` as
        the ur_description calibration yaml, URDF joints and URScript snippet
        (`hostpc.robots.ur_export`); returns {"yaml"|"urdf"|"urscript": path}."""
        from hostpc.kinematics import get_robot
        from hostpc.robots.ur_export import write_exports

        return write_exports(directory, get_robot(robot), self._check_offsets(offsets),
                             stem=self.EXPORT_STEM)

    async def rollback(self, rollback_id: str) -> np.ndarray:
        """Restore the offsets saved under `rollback_id`; returns the replaced ones."""
        try:
            saved = self._rollbacks[rollback_id]
        except KeyError:
            raise ControllerError(f"UR host offsets: unknown rollback id {rollback_id!r}") from None
        replaced = self._offsets.copy()
        self._offsets = saved.copy()
        return replaced
