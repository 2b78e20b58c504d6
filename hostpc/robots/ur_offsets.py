"""The host zero offsets of the UR driver: validated, replaced with a rollback id, exported.

`UrHostOffsets` is a collaborator of `hostpc.robots.ur.UrAdapter` that owns the offsets. A UR
controller offers no way to write joint zero offsets, so the adapter applies them on the host
(`ur.py`'s module docstring: command = wanted - o, reported = measured + o); nothing here
writes to the robot. `export_offsets` (an `OffsetExport`, hostpc.robots.base) writes them for
the software that drives the robot (`hostpc.robots.ur_export`). Angles rad.
"""

from __future__ import annotations

import logging
import math
from pathlib import Path

import numpy as np

from hostpc.errors import ControllerError
from hostpc.robots.ur_link import check_joints

logger = logging.getLogger("hostpc.robots.ur")

MAX_OFFSET_RAD = math.radians(5.0)
"""Largest host zero offset accepted by set_offsets (a bigger one is a fitting error)."""
EXPORT_STEM = "ur"
"""Exports are `ur_calibration.yaml`, `ur_joints.urdf.xml`, `ur_offsets.script`."""


def check_offsets(offsets: np.ndarray | list[float]) -> np.ndarray:
    """offsets as (6,) rad within MAX_OFFSET_RAD; ControllerError naming the joint if not."""
    values = check_joints(offsets, "offsets")
    if np.any(np.abs(values) > MAX_OFFSET_RAD):
        i = int(np.argmax(np.abs(values)))
        raise ControllerError(
            f"UR host offsets: joint {i + 1} offset {math.degrees(values[i]):.3f} deg "
            f"exceeds the limit {math.degrees(MAX_OFFSET_RAD):.1f} deg"
        )
    return values


class UrHostOffsets:
    """The host zero offsets (6,) rad of the UR at `host` (zero unless given) and the
    rollback ids of their replacements."""

    def __init__(self, host: str, offsets: np.ndarray | None = None) -> None:
        self.host = host
        self._offsets = np.zeros(6) if offsets is None else check_offsets(offsets)
        self._rollbacks: dict[str, np.ndarray] = {}
        self._rollback_counter = 0

    @property
    def values(self) -> np.ndarray:
        """The offsets now in force (6,) rad (a copy)."""
        return self._offsets.copy()

    def to_ur(self, q: np.ndarray) -> np.ndarray:
        """Reported angles (6,) -> the UR's own angles to command (q - offsets)."""
        return q - self._offsets

    def reported(self, q_ur: np.ndarray) -> np.ndarray:
        """The UR's measured angles (6,) -> reported angles (q_ur + offsets)."""
        return q_ur + self._offsets

    async def get_offsets(self) -> np.ndarray:
        """The host zero offsets (6,) rad (the UR's own calibration is not readable)."""
        return self._offsets.copy()

    async def set_offsets(self, offsets: np.ndarray) -> tuple[np.ndarray, str]:
        """Replace the host zero offsets (nothing is written to the robot); returns
        (previous offsets, rollback id)."""
        new = check_offsets(offsets)
        previous = self._offsets.copy()
        self._rollback_counter += 1
        rollback_id = f"ur-host-{self._rollback_counter}"
        self._rollbacks[rollback_id] = previous
        self._offsets = new
        logger.info("UR %s: host zero offsets set to %s (robot unchanged)", self.host, new)
        return previous, rollback_id

    async def rollback(self, rollback_id: str) -> np.ndarray:
        """Restore the offsets saved under `rollback_id`; returns the replaced ones."""
        try:
            saved = self._rollbacks[rollback_id]
        except KeyError:
            raise ControllerError(f"UR host offsets: unknown rollback id {rollback_id!r}") from None
        replaced = self._offsets.copy()
        self._offsets = saved.copy()
        return replaced

    def export_offsets(self, directory: str | Path, robot: str,
                       offsets: np.ndarray) -> dict[str, Path]:
        """Write `offsets` (6,) rad of robot model `robot` (e.g. `ur5e`) into `directory` as
        the ur_description calibration yaml, URDF joints and URScript snippet
        (`hostpc.robots.ur_export`); returns {"yaml"|"urdf"|"urscript": path}."""
        from hostpc.kinematics import get_robot
        from hostpc.robots.ur_export import write_exports

        return write_exports(directory, get_robot(robot), check_offsets(offsets),
                             stem=EXPORT_STEM)
