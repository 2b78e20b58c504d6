"""What a dataset's numbers say of its declared units: the facts behind `hostpc fit`'s units
hint (hostpc.cli.format), for a fit whose residuals are far above the stated noise, and
behind `hostpc import`'s unit warning.

Three facts. The measured positions' distances from the sensor (a cell in mm whose numbers
all lie within 5 cm reads as metres). Their spread against the robot's motion
(``unit_slip``): the nominal robot moved through the samples' joint values spreads its
flange over some RMS distance; world-frame points measured on it (a laser tracker's, a
motion capture's) spread about as much. Points that spread ten times less or more were read
in another length unit, or the joint values in another angle unit, and the unit pair that
makes the two agree is named. And their handedness (``mirrored_axes``): the nominal robot
registered rigidly onto the points (world frame and marker, ``frame_guess``) as read and
with two axes swapped; points that fit far better swapped were mapped with two of the
instrument's axes exchanged (a mirror image, which no world frame undoes), and the swap is
named."""

from __future__ import annotations

import itertools
import json
import math
import os
from dataclasses import dataclass
from typing import Any

import numpy as np

from hostpc.dataset import Dataset
from hostpc.dataset.kind_registry import csv_row_shape
from hostpc.dataset.validation import read_dataset_bytes
from hostpc.importing.csv_import import ANGLE_UNITS, LENGTH_UNITS
from hostpc.kinematics import Chain
from hostpc.kinematics.poses import forward

CLOSE_MM = 50.0
"""Positions declared in mm that all lie within this many of the sensor (5 cm) read as
metres: no cell measures every pose that close."""
FAR_M = 50.0
"""Positions declared in m that all lie this far or farther (50 m) read as millimetres."""


def declared_length_unit(path: str | os.PathLike[str]) -> str:
    """The file's `units.length` ("m" when it states none, or cannot be read here: reading
    the dataset reports that)."""
    return _declared_unit(path, "length", ("m", "mm"))


def declared_angle_unit(path: str | os.PathLike[str]) -> str:
    """The file's `units.angle`, the joint values' unit ("rad" when it states none, or
    cannot be read here)."""
    return _declared_unit(path, "angle", ("rad", "deg"))


def _declared_unit(path: str | os.PathLike[str], key: str, units: tuple[str, str]) -> str:
    try:
        document: Any = json.loads(read_dataset_bytes(path).decode("utf-8-sig"))
        unit = document.get("units", {}).get(key, units[0])
    except (OSError, ValueError, AttributeError):
        return units[0]
    return unit if unit in units else units[0]


def length_unit_hint(dataset: Dataset, declared: str, chain: Chain | None = None,
                     declared_angle: str = "rad") -> str:
    """The declared length unit, the span of the measured positions' distances in the file's
    numbers, and the unit that span suggests when it tells one. Else, with the dataset's
    ``chain``, for a kind whose positions are world-frame points (the kinds hostpc import
    writes): a unit slip (``unit_slip``) when the points do not spread as the robot's
    motion says."""
    p = dataset.samples.p
    check = f"units.length is {declared}: check that the numbers are in {declared}"
    if p is None or not np.isfinite(p).any():
        return check
    distances = np.linalg.norm(p, axis=1) * (1000.0 if declared == "mm" else 1.0)
    distances = distances[np.isfinite(distances)]
    lo, hi = float(distances.min()), float(distances.max())
    span = f"units.length is {declared}, but the positions span {lo:.3g}-{hi:.3g}"
    if declared == "mm" and hi < CLOSE_MM:
        return f"{span}: metres? set units.length m"
    if declared == "m" and lo >= FAR_M:
        return f"{span}: millimetres? set units.length mm"
    slip = None if chain is None else slip_hint(dataset, chain, declared, declared_angle)
    mirror = None if chain is None or slip else _mirror_hint(dataset, chain)
    return slip or mirror or f"{check} (the positions span {lo:.3g}-{hi:.3g})"


def _world_points(dataset: Dataset) -> np.ndarray | None:
    """The measured positions (N, 3) of a dataset whose kind's positions are world-frame
    points (the kinds hostpc import writes); None for any other kind."""
    from hostpc.dataset.kind_registry import csv_row_kinds

    p = dataset.samples.p
    return None if p is None or dataset.method not in csv_row_kinds() else p


def slip_hint(dataset: Dataset, chain: Chain, declared: str = "m",
              declared_angle: str = "rad") -> str | None:
    """The unit slip (``unit_slip``) of a dataset whose kind's positions are world-frame
    points (the kinds hostpc import writes), read in its declared units, in words with the
    next step; None when there is none (or the kind's positions are not such points)."""
    p = _world_points(dataset)
    if p is None:
        return None
    slip = unit_slip(chain, dataset.samples.q, p, declared, declared_angle)
    if slip is None:
        return None
    return (f"{unit_slip_sentence(slip, 'units.length', 'units.angle', chain.name)} "
            "(re-import with the units the numbers are in, or set the file's units)")


def _mirror_hint(dataset: Dataset, chain: Chain) -> str | None:
    """Two of the instrument's axes exchanged (``mirrored_axes``) in a dataset whose kind's
    positions are world-frame points, in words with the next step; None when there is none."""
    p = _world_points(dataset)
    if p is None:
        return None
    markers = dataset.samples.fields.get("marker")
    mirror = mirrored_axes(chain, dataset.samples.q, p, dataset.method, None if
                           markers is None else np.unique(markers, return_inverse=True)[1])
    if mirror is None:
        return None
    return (f"{mirrored_axes_sentence(mirror, chain.name)} (re-import with the "
            f"{mirror.axes[0]} and {mirror.axes[1]} columns exchanged)")


SPREAD_FACTOR = 10.0
"""Points that spread this many times less, or more, than the nominal robot's flange over
the same joint values read as numbers in another unit (a tool or marker offset changes the
spread by tens of percent, not ten times)."""
FITS_FACTOR = 3.0
"""A unit pair explains the spread when, read in it, the two agree within this factor."""
MIN_SPREAD_M = 0.01
"""Below this (1 cm) predicted and measured spread, the poses barely move: nothing to judge."""
MAX_POSES = 2000
"""The spread is judged on at most this many rows, evenly spaced (a tracker export may hold
millions)."""


def spread(points: np.ndarray) -> float:
    """RMS distance (m) of the finite rows of ``points`` (N, 3) from their centre; 0 for
    none."""
    finite = points[np.all(np.isfinite(points), axis=1)]
    if not len(finite):
        return 0.0
    return float(np.sqrt(np.mean(np.sum((finite - finite.mean(axis=0))**2, axis=1))))


def _factors(units: dict[str, float]) -> list[float]:
    """Every factor by which reading numbers in one of ``units`` as another scales them,
    1 first."""
    return sorted({round(a / b, 12) for a in units.values() for b in units.values()},
                  key=lambda f: (f != 1, abs(math.log(f))))


def _unit_times(unit: str, factor: float, units: dict[str, float]) -> str | None:
    """The unit whose numbers are ``factor`` times those of ``unit`` read as ``unit``."""
    return next((name for name, size in units.items()
                 if math.isclose(size, units[unit] * factor, rel_tol=1e-9)), None)


@dataclass(frozen=True)
class UnitSlip:
    """Measured points that do not spread as the robot's motion says: measured, predicted:
    the RMS spread (m) of the points and of the nominal flange, read in the declared units;
    length_factor, joint_factor: the factors (of reading one unit of LENGTH_UNITS,
    ANGLE_UNITS as another) that make them agree, None when no pair does; joint_span: the
    widest revolute joint's span in the declared joint unit (None without revolute joints);
    length_unit, joint_unit: the declared units."""

    measured: float
    predicted: float
    length_factor: float | None
    joint_factor: float | None
    joint_span: float | None
    length_unit: str = "m"
    joint_unit: str = "rad"

    @property
    def ratio(self) -> float:
        """How many times the points spread more (> 1) or less than the flange."""
        return self.measured / self.predicted if self.predicted > 0 else math.inf

    @property
    def suggested_units(self) -> tuple[str, str] | None:
        """The length and joint units in which the numbers agree, when both are units the
        import reads (else None)."""
        if self.length_factor is None or self.joint_factor is None:
            return None
        length = _unit_times(self.length_unit, self.length_factor, LENGTH_UNITS)
        joint = _unit_times(self.joint_unit, self.joint_factor, ANGLE_UNITS)
        return None if length is None or joint is None else (length, joint)


def unit_slip(chain: Chain, q: np.ndarray, points: np.ndarray, length_unit: str = "m",
              joint_unit: str = "rad", prismatic_unit: str | None = None) -> UnitSlip | None:
    """Do world-frame ``points`` (N, 3, m) spread as the nominal ``chain``'s flange over the
    joint values ``q`` (N, n: rad, m for prismatic joints), both read in the declared units?
    None when they agree within ``SPREAD_FACTOR`` (or neither spreads ``MIN_SPREAD_M``);
    else the facts and the factors (of reading one length or angle unit the import knows as
    another) that make them agree within ``FITS_FACTOR``, the fewest changes first.
    Prismatic joints are read in the length unit unless ``prismatic_unit`` names theirs."""
    if q.ndim != 2 or q.shape[1] != chain.n or not len(q):
        return None
    rows = np.unique(np.linspace(0, len(q) - 1, min(len(q), MAX_POSES)).astype(int))
    q, points = q[rows], points[rows]
    keep = np.all(np.isfinite(q), axis=1)
    q, points = q[keep], points[keep]
    if not len(q):
        return None
    prismatic = np.asarray(chain.joint_is_prismatic, dtype=bool)
    measured = spread(points)
    predicted = spread(forward(chain, q).T_base_flange[:, :3, 3])
    if max(measured, predicted) < MIN_SPREAD_M or (
            predicted > 0 and 1 / SPREAD_FACTOR <= measured / predicted <= SPREAD_FACTOR):
        return None
    span = (float(np.max(np.ptp(q[:, ~prismatic], axis=0))) / ANGLE_UNITS[joint_unit]
            if (~prismatic).any() else None)
    best: tuple[int, float, float, float] | None = None
    for length_factor, joint_factor in itertools.product(_factors(LENGTH_UNITS),
                                                         _factors(ANGLE_UNITS)):
        read = q.copy()
        read[:, ~prismatic] *= joint_factor
        if prismatic_unit is None:
            read[:, prismatic] *= length_factor
        flange = spread(forward(chain, read).T_base_flange[:, :3, 3])
        if flange <= 0:
            continue
        off = abs(math.log(measured * length_factor / flange))
        key = (int(length_factor != 1) + int(joint_factor != 1), off)
        if off < math.log(FITS_FACTOR) and (best is None or key < best[:2]):
            best = (*key, length_factor, joint_factor)
    return UnitSlip(measured, predicted, None if best is None else best[2],
                    None if best is None else best[3], span, length_unit, joint_unit)


def unit_slip_sentence(slip: UnitSlip, length_option: str, joint_option: str,
                       robot: str) -> str:
    """The facts of a unit slip in words, naming the declared units after ``length_option``
    and ``joint_option`` ("--length-unit", "units.length"), and what the numbers suggest;
    ends before the next step."""
    length, joint = slip.length_unit, slip.joint_unit
    times = slip.ratio if slip.ratio >= 1 else 1 / slip.ratio
    more = "more" if slip.ratio >= 1 else "less"
    facts = (f"the measured points spread {slip.measured * 1e3:.3g} mm (RMS about their "
             f"centre) read with {length_option} {length}, where the nominal {robot} moved "
             f"through these joint values (read with {joint_option} {joint}) spreads its "
             f"flange {slip.predicted * 1e3:.3g} mm: {times:.3g} times {more}")
    if slip.length_factor is None or slip.joint_factor is None:
        return f"{facts}; no length or joint unit explains it: check the columns and the robot"
    changed = []
    if slip.length_factor != 1:
        other = _unit_times(length, slip.length_factor, LENGTH_UNITS)
        changed.append(f"the lengths look like {other}, not {length}" if other else
                       f"the lengths look {_times(slip.length_factor, LENGTH_UNITS)}")
    if slip.joint_factor != 1:
        span = ("" if slip.joint_span is None else
                f"every revolute joint spans under {slip.joint_span:.3g} {joint} with "
                f"{joint_option} {joint}: ")
        other = _unit_times(joint, slip.joint_factor, ANGLE_UNITS)
        changed.append(f"{span}the joint values look like {other}, not {joint}" if other
                       else f"{span}the joint values look "
                       f"{_times(slip.joint_factor, ANGLE_UNITS)}")
    return f"{facts}; {' and '.join(changed)}"


def _times(factor: float, units: dict[str, float]) -> str:
    """'1000 times too small (m read as mm?)' for a factor of 1000; 'too large' below 1."""
    size = (f"{factor:.4g} times too small" if factor > 1 else
            f"{1 / factor:.4g} times too large")
    pair = next(((a, b) for a, b in itertools.permutations(units, 2)
                 if math.isclose(units[a] / units[b], factor, rel_tol=1e-9)), None)
    return size if pair is None else f"{size} ({pair[0]} read as {pair[1]}?)"


MIRROR_FACTOR = 5.0
"""Points that the nominal robot fits this many times better with two axes swapped than as
read are a mirror image (a wrong axis mapping fits no better than a few times, by chance)."""
AXIS_SWAPS = (("x", "y"), ("y", "z"), ("x", "z"))


@dataclass(frozen=True)
class MirroredAxes:
    """World-frame points that fit the nominal robot far better with two axes swapped:
    as_read, swapped: the RMS (m) of the nominal robot registered onto the points as read
    and with ``axes`` swapped (every swap fits alike, a mirror being one up to a rotation;
    ``axes`` is the one whose world frame turns least from the instrument's, the usual
    mounting)."""

    as_read: float
    swapped: float
    axes: tuple[str, str]


def _registered(T_base_flange: np.ndarray, points: np.ndarray,
                marker_index: np.ndarray | None) -> tuple[float, float]:
    """(RMS (m), world rotation angle (rad)) of the nominal flange's markers registered
    rigidly onto ``points`` (``frame_guess.guess_world_point``)."""
    from hostpc.importing.frame_guess import guess_world_point

    W, markers = guess_world_point(T_base_flange, points, marker_index)
    index = np.zeros(len(points), dtype=np.int64) if marker_index is None else marker_index
    in_base = (np.einsum("nij,nj->ni", T_base_flange[:, :3, :3], markers[index])
               + T_base_flange[:, :3, 3])
    residual = in_base @ W[:3, :3].T + W[:3, 3] - points
    angle = math.acos(min(1.0, max(-1.0, (float(np.trace(W[:3, :3])) - 1.0) / 2.0)))
    return float(np.sqrt(np.mean(np.sum(residual**2, axis=1)))), angle


def mirrored_axes(chain: Chain, q: np.ndarray, points: np.ndarray, method: str,
                  marker_index: np.ndarray | None = None) -> MirroredAxes | None:
    """Do world-frame ``points`` (N, 3, m) of a point kind (``method``) fit the nominal
    ``chain`` moved through ``q`` (N, n) ``MIRROR_FACTOR`` times better with two axes
    swapped than as read? The facts when so, else None (also for full poses, whose
    orientations a swap would change too, and for too few or non-finite rows)."""
    from hostpc.errors import InputError

    if csv_row_shape(method) != "point" or q.ndim != 2 or q.shape[1] != chain.n:
        return None
    rows = np.unique(np.linspace(0, len(q) - 1, min(len(q), MAX_POSES)).astype(int))
    keep = rows[np.all(np.isfinite(q[rows]), axis=1) & np.all(np.isfinite(points[rows]),
                                                              axis=1)]
    index = None if marker_index is None else np.asarray(marker_index, dtype=np.int64)[keep]
    try:
        T_base_flange = forward(chain, q[keep]).T_base_flange
        as_read, _ = _registered(T_base_flange, points[keep], index)
        swaps = []
        for a, b in AXIS_SWAPS:
            order = [0, 1, 2]
            order["xyz".index(a)], order["xyz".index(b)] = "xyz".index(b), "xyz".index(a)
            rms, angle = _registered(T_base_flange, points[keep][:, order], index)
            swaps.append((angle, rms, (a, b)))
    except (InputError, np.linalg.LinAlgError):
        return None
    _, swapped, axes = min(swaps)
    if not swapped * MIRROR_FACTOR < as_read:
        return None
    return MirroredAxes(as_read, swapped, axes)


def mirrored_axes_sentence(mirror: MirroredAxes, robot: str) -> str:
    """The facts of mirrored axes in words; ends before the next step."""
    a, b = mirror.axes
    return (f"the measured points are a mirror image of the nominal {robot}'s motion: "
            f"registered onto them as read, it misses them by {mirror.as_read * 1e3:.3g} mm "
            f"RMS, with {a} and {b} exchanged by {mirror.swapped * 1e3:.3g} mm: two of the "
            "instrument's axes were exchanged in the mapping")
