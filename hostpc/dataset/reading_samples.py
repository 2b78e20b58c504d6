"""Reading the samples of a ``zerocal-dataset/1`` document into ``Samples`` (SI).

Every sample is checked against its method (the fields it may and must have, joint counts,
covariances, approach signs) and the values are gathered into arrays, NaN / -1 where an
optional value is absent. Raises ``hostpc.dataset.schema.FieldError`` naming the sample
index and field; ``reading`` turns it into a ``DatasetError``.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from hostpc.dataset import schema
from hostpc.dataset.model import FloatArray, Samples
from hostpc.dataset.schema import FieldError, Loc, show
from hostpc.dataset.units import Units

# Sample fields each method accepts (besides these, a sample field is an error).
_CONTEXT_FIELDS = frozenset({"t", "approach", "temperature", "speed", "extra"})
_SAMPLE_FIELDS: dict[str, frozenset[str]] = {
    "stereo_target": frozenset({"q", "p", "cov", "sigma", "uv"}) | _CONTEXT_FIELDS,
    "sphere_probe": frozenset({"q", "sigma", "group"}) | _CONTEXT_FIELDS,
    "dual_loop": frozenset({"chain", "q_head", "q_arm", "p", "cov", "sigma", "uv"})
    | _CONTEXT_FIELDS,
}
_SAMPLE_HINTS = {
    ("dual_loop", "q"): " (dual_loop uses 'q_arm' and 'q_head')",
    ("stereo_target", "q_arm"): " (use 'q')",
    ("sphere_probe", "q_arm"): " (use 'q')",
    ("sphere_probe", "cov"): " (give the contact-distance 'sigma')",
    ("sphere_probe", "p"): " (a contact has no measured point)",
}

_SYMMETRY_TOLERANCE = 1e-6  # relative to the largest entry of the matrix


def _require(sample: schema.SampleSchema, loc: Loc, name: str, hint: str = "") -> Any:
    value = getattr(sample, name)
    if value is None:
        raise FieldError((*loc, name), "required field missing" + hint)
    return value


def _check_joint_count(loc: Loc, values: list[float], n: int, label: str) -> None:
    if len(values) != n:
        raise FieldError(loc, f"expected {n} joint angles for {label}, got {len(values)}")


def _check_covariance(loc: Loc, cov: FloatArray) -> None:
    """(3, 3) covariance in m^2: finite, symmetric, positive definite."""
    if not np.all(np.isfinite(cov)):
        raise FieldError(loc, "out of range after unit conversion")
    scale = float(np.max(np.abs(cov)))
    if float(np.max(np.abs(cov - cov.T))) > _SYMMETRY_TOLERANCE * scale:
        raise FieldError(loc, "not symmetric")
    try:
        lower = np.linalg.cholesky(cov)
    except np.linalg.LinAlgError:
        raise FieldError(loc, "not positive definite") from None
    if not (np.all(np.isfinite(lower)) and np.all(np.diag(lower) > 0)):
        raise FieldError(loc, "not positive definite")


def _positive(loc: Loc, value: float) -> float:
    if not value > 0:
        raise FieldError(loc, f"must be positive, got {show(value)}")
    return value


class _Columns:
    """Per-sample optional values gathered into arrays (NaN / -1 where absent)."""

    def __init__(self, n_samples: int) -> None:
        self.n_samples = n_samples
        self.values: dict[str, list[Any]] = {}

    def put(self, name: str, index: int, value: Any) -> None:
        self.values.setdefault(name, [None] * self.n_samples)[index] = value

    def given(self, name: str) -> bool:
        return name in self.values

    def floats(self, name: str, convert: Callable[[Any], FloatArray]) -> FloatArray:
        column = self.values.get(name, [None] * self.n_samples)
        return convert([np.nan if v is None else v for v in column])

    def rows(self, name: str, width: int) -> FloatArray:
        """Rows of possibly different length, NaN-padded to ``width``."""
        out = np.full((self.n_samples, width), np.nan)
        for i, row in enumerate(self.values.get(name, [])):
            if row is not None:
                out[i, : len(row)] = row
        return out


def read_samples(
    samples: list[schema.SampleSchema],
    method: str,
    n_joints: int | None,
    robot_label: str,
    units: Units,
) -> Samples:
    """Check every sample against ``method`` and build the arrays in SI."""
    allowed = _SAMPLE_FIELDS[method]
    columns = _Columns(len(samples))
    head_width: tuple[int, int] | None = None  # (width, first sample)
    arm_width: dict[str, tuple[int, int]] = {}
    extra_names: dict[str, None] = {}

    for i, sample in enumerate(samples):
        loc: Loc = ("samples", i)
        for name in schema.SAMPLE_FIELDS:
            if name in sample.model_fields_set and name not in allowed:
                hint = _SAMPLE_HINTS.get((method, name), "")
                raise FieldError((*loc, name), f"not a field of method '{method}'{hint}")

        if method == "dual_loop":
            chain = _require(sample, loc, "chain", " ('left' or 'right')")
            q_head = _require(sample, loc, "q_head")
            q = _require(sample, loc, "q_arm")
            for name, values in (("q_head", q_head), ("q_arm", q)):
                if not values:
                    raise FieldError((*loc, name), "expected at least one joint angle")
            if head_width is None:
                head_width = (len(q_head), i)
            _check_joint_count(
                (*loc, "q_head"),
                q_head,
                head_width[0],
                f"the head (as in samples[{head_width[1]}].q_head)",
            )
            width, first = arm_width.setdefault(chain, (len(q), i))
            _check_joint_count(
                (*loc, "q_arm"),
                q,
                width,
                f"chain '{chain}' (as in samples[{first}].q_arm)",
            )
            columns.put("chain", i, chain)
            columns.put("q_head", i, q_head)
        else:
            q = _require(sample, loc, "q")
            assert n_joints is not None
            _check_joint_count((*loc, "q"), q, n_joints, robot_label)
        columns.put("q", i, q)

        if method == "sphere_probe":
            sigma = _positive((*loc, "sigma"), _require(sample, loc, "sigma"))
            columns.put("sigma", i, sigma)
            if sample.group is not None:
                columns.put("group", i, sample.group)
        else:
            columns.put("p", i, _require(sample, loc, "p"))
            if sample.cov is not None and sample.sigma is not None:
                raise FieldError((*loc, "sigma"), "give either 'cov' or 'sigma', not both")
            if sample.cov is not None:
                cov = units.area(sample.cov)
            elif sample.sigma is not None:
                sigma_m = float(units.length(_positive((*loc, "sigma"), sample.sigma)))
                variance = sigma_m * sigma_m  # float product: inf on overflow, no exception
                if not 0 < variance < np.inf:
                    raise FieldError((*loc, "sigma"), f"out of range, got {show(sample.sigma)}")
                cov = variance * np.eye(3)
            else:
                raise FieldError((*loc, "cov"), "required field missing (or give 'sigma')")
            _check_covariance((*loc, "cov" if sample.cov is not None else "sigma"), cov)
            columns.put("cov", i, cov)

        if sample.approach is not None:
            if len(sample.approach) != len(q):
                raise FieldError(
                    (*loc, "approach"),
                    f"expected {len(q)} values (one per joint), got {len(sample.approach)}",
                )
            for j, sign in enumerate(sample.approach):
                if sign not in (1.0, -1.0):
                    raise FieldError((*loc, "approach", j), f"expected +1 or -1, got {show(sign)}")
            columns.put("approach", i, sample.approach)
        for name in ("t", "temperature", "speed", "uv"):
            if getattr(sample, name) is not None:
                columns.put(name, i, getattr(sample, name))
        for key, value in (sample.extra or {}).items():
            extra_names[key] = None
            columns.put("extra." + key, i, value)

    speed = columns.floats("speed", units.speed)
    for index in np.flatnonzero(np.isinf(speed)):
        raise FieldError(("samples", int(index), "speed"), "out of range after unit conversion")

    width = max(len(row) for row in columns.values["q"])
    is_dual = method == "dual_loop"
    uv = None
    if columns.given("uv"):
        uv = np.full((len(samples), 2, 2), np.nan)
        for i, value in enumerate(columns.values["uv"]):
            if value is not None:
                uv[i] = value
    return Samples(
        q=units.angle(columns.rows("q", width)),
        p=None if method == "sphere_probe" else units.length(columns.values["p"]),
        cov=None if method == "sphere_probe" else np.asarray(columns.values["cov"]),
        sigma=units.length(columns.values["sigma"]) if method == "sphere_probe" else None,
        t=columns.floats("t", units.time),
        temperature=columns.floats("temperature", np.asarray),
        speed=speed,
        approach=columns.rows("approach", width),
        group=_groups(columns),
        extra={k: columns.floats("extra." + k, np.asarray) for k in extra_names},
        uv=uv,
        chain=np.asarray(columns.values["chain"], dtype=np.str_) if is_dual else None,
        q_head=units.angle(columns.values["q_head"]) if is_dual else None,
    )


def _groups(columns: _Columns) -> Any:
    """(N,) int group index, -1 where absent."""
    column = columns.values.get("group", [None] * columns.n_samples)
    return np.asarray([-1 if g is None else g for g in column], dtype=np.int64)
