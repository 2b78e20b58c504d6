"""Drift between calibrations of one robot (pure: run entries in, findings out).

A joint's zero is the offset a calibration left in the controller (`new_deg`). Between
two consecutive calibrations of one robot it should not move; when it does, something
happened (a collision, a slipping encoder, a motor swap). A finding is raised for a joint
whose zero moved by more than `threshold_deg`, or by more than `z_limit` times the
uncertainty of the difference (sqrt(sigma_a^2 + sigma_b^2)): more than the two fits'
own uncertainties say it could by chance.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

DEFAULT_THRESHOLD_DEG = 0.02
DEFAULT_Z_LIMIT = 6.0


@dataclass(frozen=True)
class DriftFinding:
    """Joint `label` of robot `serial` moved by `moved_deg` between runs `from_run` and
    `to_run` (archive ids); `z` is that move over its uncertainty (None if unknown)."""

    serial: str
    label: str
    from_run: int
    to_run: int
    moved_deg: float
    z: float | None
    reason: str

    def as_dict(self) -> dict[str, Any]:
        return {"serial": self.serial, "joint": self.label, "from_run": self.from_run,
                "to_run": self.to_run, "moved_deg": self.moved_deg, "z": self.z,
                "reason": self.reason}


ZeroPoint = tuple[int, str, float, float | None]


def zero_series(runs: list[dict[str, Any]]) -> dict[str, list[ZeroPoint]]:
    """Per joint label: (run id, time, zero after the run in deg, sigma in deg) over the
    runs that determined it, in the order given."""
    series: dict[str, list[ZeroPoint]] = {}
    for run in runs:
        for offset in run.get("offsets", []):
            if offset.get("new_deg") is None or not offset.get("pushed", False):
                continue
            series.setdefault(offset["label"], []).append(
                (int(run["id"]), str(run["started_at"]), float(offset["new_deg"]),
                 None if offset.get("sigma_deg") is None else float(offset["sigma_deg"])))
    return series


def drift_findings(runs: list[dict[str, Any]], threshold_deg: float = DEFAULT_THRESHOLD_DEG,
                   z_limit: float = DEFAULT_Z_LIMIT) -> list[DriftFinding]:
    """Drift findings over archived runs (any robots; each robot's runs in time order)."""
    by_robot: dict[str, list[dict[str, Any]]] = {}
    for run in runs:
        by_robot.setdefault(str(run["serial"]), []).append(run)
    findings = []
    for serial, robot_runs in by_robot.items():
        for label, points in zero_series(robot_runs).items():
            for (run_a, _, zero_a, sigma_a), (run_b, _, zero_b, sigma_b) in zip(
                    points, points[1:], strict=False):
                moved = zero_b - zero_a
                sigma = (math.hypot(sigma_a, sigma_b)
                         if sigma_a is not None and sigma_b is not None else None)
                z = abs(moved) / sigma if sigma else None
                reasons = []
                if abs(moved) > threshold_deg:
                    reasons.append(f"moved {moved:+.4f} deg > threshold {threshold_deg:g} deg")
                if z is not None and z > z_limit:
                    reasons.append(f"{z:.1f} sigma > {z_limit:g} sigma")
                if reasons:
                    findings.append(DriftFinding(serial, label, run_a, run_b, moved, z,
                                                 "; ".join(reasons)))
    return findings


def fleet_summary(runs: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per robot: its last run's verdict and time, and its largest zero move between any
    two consecutive calibrations (deg), robots moving most first."""
    by_robot: dict[str, list[dict[str, Any]]] = {}
    for run in runs:
        by_robot.setdefault(str(run["serial"]), []).append(run)
    rows = []
    for serial, robot_runs in by_robot.items():
        last = robot_runs[-1]
        largest = 0.0
        for points in zero_series(robot_runs).values():
            for a, b in zip(points, points[1:], strict=False):
                largest = max(largest, abs(b[2] - a[2]))
        rows.append({"serial": serial, "model": last.get("model", ""), "runs": len(robot_runs),
                     "last_verdict": last["verdict"], "last_run": last["started_at"],
                     "largest_zero_move_deg": largest})
    return sorted(rows, key=lambda row: -float(row["largest_zero_move_deg"]))
