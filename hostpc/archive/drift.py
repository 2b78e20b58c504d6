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
from collections.abc import Sequence
from dataclasses import asdict, dataclass

from hostpc.archive.rows import ArchivedRun
from hostpc.json_object import JsonObject

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

    def to_json(self) -> JsonObject:
        """The finding as `hostpc history --json` prints it."""
        return {"serial": self.serial, "joint": self.label, "from_run": self.from_run,
                "to_run": self.to_run, "moved_deg": self.moved_deg, "z": self.z,
                "reason": self.reason}


@dataclass(frozen=True)
class FleetRow:
    """One robot in the fleet view: its last run's verdict and time (ISO 8601 UTC), its
    run count, and its largest zero move between two consecutive calibrations (deg)."""

    serial: str
    model: str
    runs: int
    last_verdict: str
    last_run: str
    largest_zero_move_deg: float

    def to_json(self) -> JsonObject:
        """The row as `hostpc history --json` prints it."""
        return asdict(self)


ZeroPoint = tuple[int, str, float, float | None]


def zero_series(runs: Sequence[ArchivedRun]) -> dict[str, list[ZeroPoint]]:
    """Per joint label: (run id, time, zero after the run in deg, sigma in deg) over the
    runs that determined it, in the order given."""
    series: dict[str, list[ZeroPoint]] = {}
    for run in runs:
        for offset in run.offsets:
            if offset.new_deg is None or not offset.pushed:
                continue
            series.setdefault(offset.label, []).append(
                (run.id, run.started_at, offset.new_deg, offset.sigma_deg))
    return series


def by_robot(runs: Sequence[ArchivedRun]) -> dict[str, list[ArchivedRun]]:
    """The runs per robot serial (in the order given; robots in order of their first run)."""
    robots: dict[str, list[ArchivedRun]] = {}
    for run in runs:
        robots.setdefault(run.serial, []).append(run)
    return robots


def drift_findings(runs: Sequence[ArchivedRun], threshold_deg: float = DEFAULT_THRESHOLD_DEG,
                   z_limit: float = DEFAULT_Z_LIMIT) -> list[DriftFinding]:
    """Drift findings over archived runs (any robots; each robot's runs in time order)."""
    findings = []
    for serial, robot_runs in by_robot(runs).items():
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


def fleet_summary(runs: Sequence[ArchivedRun]) -> list[FleetRow]:
    """Per robot: its last run's verdict and time, and its largest zero move between any
    two consecutive calibrations (deg), robots moving most first."""
    rows = []
    for serial, robot_runs in by_robot(runs).items():
        last = robot_runs[-1]
        largest = 0.0
        for points in zero_series(robot_runs).values():
            for a, b in zip(points, points[1:], strict=False):
                largest = max(largest, abs(b[2] - a[2]))
        rows.append(FleetRow(serial, last.model, len(robot_runs), last.verdict,
                             last.started_at, largest))
    return sorted(rows, key=lambda row: -row.largest_zero_move_deg)
