"""Priors and holds on named parameters.

A PRIOR says a parameter is known to within a tolerance: `tool.x=0.045+-0.0005m` (a camera
mount from a CAD drawing), `joint_offsets.q1=0+-0.01deg`. It enters the fit as one more
residual, whitened by its sigma: (x_i - value) / sigma. It is an observation like any other:
it adds a row to the Jacobian, so it can make a direction identifiable that the measurements
alone leave free (the identifiability analysis sees the prior rows), and it enters the
covariance.

A HOLD keeps a parameter at its start value (the nominal, zero delta): the solver never moves
it, so after the fit it is bit-identical to the start.

A PRIOR BLOCK is a prior on several parameters at once with a full covariance (a cell
reference's frame, `hostpc reference`: a fitted frame's values are correlated, so their
marginal sigmas alone would claim too much in some directions and too little in others). It
enters as K residuals whitened by the inverse Cholesky factor of its covariance:
L^-1 (x_block - value), C = L L^T. In the dataset: `"prior_blocks": [{"names": [...],
"value": [...], "covariance": [[...]]}]` (SI), beside `priors`; a name may not be in two
priors. A block may also say how its value moves with the dataset's shared error
(`"shared_sensitivity"`: K x Ks, the value's change per unit of the shared error,
+d value / d delta, e.g. a reference frame recorded with the same stereo rig, whose
calibration error it carries): its covariance then includes that part, and the fit's
covariance counts it as the SAME error as the measurements' (hostpc.fitting.shared_errors),
not as independent noise.

Where they come from (all end up in the dataset's top-level `priors` and `hold` fields, which
the fit reads from the problem's dataset):
- the dataset file: `"priors": ["tool.x=0.045+-0.0005m", ...]` or
  `{"tool.x": {"value": 0.045, "sigma": 0.0005, "unit": "m"}}` (unit optional: SI),
  `"hold": ["tool.rz", ...]`;
- the CLI: `--prior NAME=VALUE+-SIGMA[UNIT]` (repeatable), `--hold NAME[,NAME...]`;
- Python: `hostpc.fit(dataset, priors=[...] or {...}, hold=[...])`.

Units as printed: m, mm, um for lengths; rad, mrad, urad, deg for angles; none means the
parameter's SI unit, the one its layout states (a joint offset's is its joint's:
``hostpc.model.joint_offsets.unit``, rad for a revolute joint, m for a prismatic one). An
unknown name or a unit that does not fit raises InputError (one line, naming the units
that fit), as do a value outside the dataset's physical ranges (|m| <= 100, |rad| <= 100),
a sigma not finite or below 1e-12 (SI), and a parameter both held and given a prior.
"""

from __future__ import annotations

import dataclasses
import math
import re
from collections.abc import Collection, Iterable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from hostpc.dataset.validation import MAX_ABS_CONTEXT, MAX_ANGLE_RAD, MAX_POSITION_M
from hostpc.errors import InputError
from hostpc.json_object import JsonObject

_SCALE = {"m": ("m", 1.0), "mm": ("m", 1e-3), "um": ("m", 1e-6),
          "rad": ("rad", 1.0), "mrad": ("rad", 1e-3), "urad": ("rad", 1e-6),
          "deg": ("rad", math.pi / 180.0)}
_NUMBER = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
_PRIOR = re.compile(rf"^\s*([A-Za-z_][\w.]*)\s*=\s*({_NUMBER})\s*(?:\+-|±|\+/-)\s*({_NUMBER})"
                    r"\s*([A-Za-z]*)\s*$")


@dataclass(frozen=True)
class Prior:
    """name: parameter name; value and sigma in the parameter's SI unit (sigma > 0)."""

    name: str
    value: float
    sigma: float


@dataclass(frozen=True)
class Constraints:
    """The priors and holds of a problem, resolved against its parameter layout.

    index: (K,) parameter index of each prior; value, sigma: (K,) SI (sigma: the marginal
    one of a prior block's parameter); held: (P,) bool; whitening: (K, K) the matrix that
    whitens x[index] - value when prior blocks are present (block-diagonal: 1 / sigma for a
    single prior, L^-1 for a block), None: diag(1 / sigma); shared: (K, Ks) how each prior's
    value moves with the dataset's shared error (zero rows for priors that do not), None:
    no block states one."""

    priors: tuple[Prior, ...]
    index: np.ndarray
    value: np.ndarray
    sigma: np.ndarray
    held: np.ndarray
    whitening: np.ndarray | None = None
    shared: np.ndarray | None = None

    def whitened_shared(self) -> np.ndarray | None:
        """(K, Ks) `shared` whitened as the residuals are, or None."""
        if self.shared is None:
            return None
        if self.whitening is not None:
            whitened: np.ndarray = self.whitening @ self.shared
            return whitened
        return self.shared / self.sigma[:, None]

    def residuals(self, x: np.ndarray) -> np.ndarray:
        """(K,) whitened prior residuals (x_i - value) / sigma (or whitening @ (x - value))."""
        difference = np.asarray(x)[self.index] - self.value
        if self.whitening is not None:
            whitened: np.ndarray = self.whitening @ difference
            return whitened
        return difference / self.sigma

    def jacobian(self, size: int) -> np.ndarray:
        """(K, P) derivative of the whitened prior residuals by x."""
        J = np.zeros((self.index.size, size))
        if self.whitening is not None:
            J[:, self.index] = self.whitening
            return J
        J[np.arange(self.index.size), self.index] = 1.0 / self.sigma
        return J

    def cost(self, x: np.ndarray) -> float:
        """0.5 * sum of squared whitened prior residuals."""
        r = self.residuals(x)
        return float(0.5 * r @ r)


MIN_PRIOR_SIGMA = 1e-12
"""Smallest prior sigma (in the parameter's SI unit): below it the whitened residual
overflows the solver's precision; hold the parameter instead."""
_PRIOR_LIMIT = {"m": MAX_POSITION_M, "rad": MAX_ANGLE_RAD}
"""Largest |value| (and sigma) of a prior per SI unit: the dataset's physical ranges
(hostpc.dataset.validation); other units get MAX_ABS_CONTEXT."""


def _convert(name: str, number: float, unit: str, param_unit: str, what: str) -> float:
    if not unit:
        return number
    if unit == param_unit:
        return number
    if unit not in _SCALE or _SCALE[unit][0] != param_unit:
        fitting = [u for u, (base, _) in _SCALE.items() if base == param_unit]
        give = (f"; give it in {', '.join(fitting)}" if fitting
                else f"; give it in {param_unit} with no unit")
        raise InputError(f"prior {name}: unit {unit!r} does not fit the parameter's unit "
                         f"{param_unit!r} ({what}{give})")
    return number * _SCALE[unit][1]


def parse_prior(text: str, units: Mapping[str, str]) -> Prior:
    """`NAME=VALUE+-SIGMA[UNIT]` -> Prior in SI. units: parameter name -> SI unit."""
    match = _PRIOR.match(str(text))
    if not match:
        raise InputError(f"prior {text!r}: expected NAME=VALUE+-SIGMA[UNIT], e.g. "
                         "tool.x=0.045+-0.0005m")
    name, value, sigma, unit = match.groups()
    return make_prior(name, float(value), float(sigma), unit, units)


def make_prior(name: str, value: float, sigma: float, unit: str,
               units: Mapping[str, str]) -> Prior:
    """A Prior from its parts (value, sigma in `unit`, '' for SI), checked against units."""
    if name not in units:
        known = ", ".join(sorted(units)) or "none"
        raise InputError(f"prior {name}: unknown parameter (this model has: {known})")
    value = _convert(name, value, unit, units[name], "value")
    sigma = _convert(name, sigma, unit, units[name], "sigma")
    if not (math.isfinite(value) and math.isfinite(sigma) and sigma > 0.0):
        raise InputError(f"prior {name}: value must be finite and sigma positive")
    unit = units[name]
    limit = _PRIOR_LIMIT.get(unit, MAX_ABS_CONTEXT)
    if abs(value) > limit:
        raise InputError(f"prior {name}: value {value:.6g} {unit} is outside the physical "
                         f"range (|value| <= {limit:g} {unit})")
    if not MIN_PRIOR_SIGMA <= sigma <= limit:
        raise InputError(f"prior {name}: sigma {sigma:.6g} {unit} is outside "
                         f"[{MIN_PRIOR_SIGMA:g}, {limit:g}] {unit}")
    return Prior(name, value, sigma)


def _prior_entries(raw: Any) -> list[Any]:
    """The dataset's `priors` as a list of strings or (name, mapping) pairs."""
    if raw is None:
        return []
    if isinstance(raw, str):
        return [raw]
    if isinstance(raw, Mapping):
        return list(raw.items())
    if isinstance(raw, list | tuple):
        return list(raw)
    raise InputError("priors: expected a list of NAME=VALUE+-SIGMA strings or a mapping")


def hold_names(raw: Any) -> list[str]:
    """The names of `hold` (a list, or comma-separated strings)."""
    if raw is None:
        return []
    items = [raw] if isinstance(raw, str) else raw
    if not isinstance(items, list | tuple):
        raise InputError("hold: expected a list of parameter names")
    names: list[str] = []
    for item in items:
        if not isinstance(item, str):
            raise InputError(f"hold: expected parameter names, got {item!r}")
        names += [n.strip() for n in item.split(",") if n.strip()]
    return names


def constraints_for(extra_fields: Mapping[str, Any], names: tuple[str, ...],
                    units: tuple[str, ...]) -> Constraints | None:
    """Resolve a dataset's `priors`/`hold` against a layout; None if it has neither."""
    raw_priors, raw_hold = extra_fields.get("priors"), extra_fields.get("hold")
    raw_blocks = extra_fields.get("prior_blocks")
    if not raw_priors and not raw_hold and not raw_blocks:
        return None
    unit_of = dict(zip(names, units, strict=True))
    priors: list[Prior] = []
    for entry in _prior_entries(raw_priors):
        if isinstance(entry, str):
            priors.append(parse_prior(entry, unit_of))
        elif isinstance(entry, tuple) and isinstance(entry[1], Mapping):
            spec = entry[1]
            try:
                value, sigma = float(spec["value"]), float(spec["sigma"])
            except (KeyError, TypeError, ValueError):
                raise InputError(f"prior {entry[0]}: expected value and sigma numbers") from None
            priors.append(make_prior(str(entry[0]), value, sigma, str(spec.get("unit", "")),
                                     unit_of))
        else:
            raise InputError(f"prior {entry!r}: expected NAME=VALUE+-SIGMA")
    whitening: np.ndarray | None = None
    shared: np.ndarray | None = None
    if raw_blocks:
        entries = _block_entries(raw_blocks)
        blocks = [prior_block(entry, unit_of) for entry in entries]
        whitening = block_whitening([np.diag(1.0 / np.array([p.sigma for p in priors]))]
                                    + [w for _, w in blocks])
        shared = _shared_rows(len(priors), [len(b) for b, _ in blocks], entries)
        priors += [p for block, _ in blocks for p in block]
    seen: set[str] = set()
    for prior in priors:
        if prior.name in seen:
            raise InputError(f"prior {prior.name}: given twice (a prior and a prior block, "
                             "or two blocks); keep one")
        seen.add(prior.name)
    held = np.zeros(len(names), dtype=bool)
    given_prior = {p.name for p in priors}
    for name in hold_names(raw_hold):
        if name not in unit_of:
            raise InputError(f"hold {name}: unknown parameter (this model has: "
                             f"{', '.join(names)})")
        if name in given_prior:
            raise InputError(f"{name} is both held and given a prior: a held parameter "
                             "stays at its nominal, so drop one of the two")
        held[names.index(name)] = True
    index = np.array([names.index(p.name) for p in priors], dtype=int)
    return Constraints(tuple(priors), index, np.array([p.value for p in priors], float),
                       np.array([p.sigma for p in priors], float), held, whitening, shared)


def _shared_rows(n_single: int, sizes: list[int], entries: list[JsonObject]
                 ) -> np.ndarray | None:
    """(K, Ks) the blocks' `shared_sensitivity` stacked under `n_single` zero rows (the
    single priors'), zero rows for a block without one; None if no block has one."""
    given = [entry.get("shared_sensitivity") for entry in entries]
    if all(g is None for g in given):
        return None
    try:
        parts = [None if g is None else np.asarray(g, dtype=float) for g in given]
    except (TypeError, ValueError):
        raise InputError("prior_blocks: shared_sensitivity must be numbers") from None
    width = {p.shape[1] for p in parts if p is not None and p.ndim == 2}
    if len(width) != 1 or any(p is not None and (p.shape != (k, *width) or
                                                 not np.all(np.isfinite(p)))
                              for p, k in zip(parts, sizes, strict=True)):
        raise InputError("prior_blocks: shared_sensitivity must be finite, one row per name "
                         "and the same width in every block")
    (ks,) = width
    return np.vstack([np.zeros((n_single, ks))]
                     + [np.zeros((k, ks)) if p is None else p
                        for p, k in zip(parts, sizes, strict=True)])


def _block_entries(raw: Any) -> list[JsonObject]:
    """The dataset's ``prior_blocks`` JSON: a list of objects."""
    if not isinstance(raw, list | tuple) or not all(isinstance(e, dict) for e in raw):
        raise InputError("prior_blocks: expected a list of {names, value, covariance}")
    return list(raw)


def prior_block(entry: JsonObject, units: Mapping[str, str]
                ) -> tuple[list[Prior], np.ndarray]:
    """One prior block -> (its Priors with marginal sigmas, its (K, K) whitening L^-1).
    InputError if a name is unknown, the sizes disagree or the covariance is not positive
    definite."""
    names = [str(n) for n in entry.get("names", [])]
    try:
        value = np.asarray(entry.get("value"), dtype=float).reshape(-1)
        covariance = np.asarray(entry.get("covariance"), dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"prior block {', '.join(names)}: value and covariance must be "
                         "numbers") from None
    k = len(names)
    if k == 0 or value.shape != (k,) or covariance.shape != (k, k):
        raise InputError(f"prior block {', '.join(names) or '(no names)'}: expected {k} "
                         f"values and a {k}x{k} covariance")
    if not (np.all(np.isfinite(covariance)) and np.allclose(covariance, covariance.T,
                                                            rtol=1e-9, atol=0.0)):
        raise InputError(f"prior block {', '.join(names)}: covariance not finite and "
                         "symmetric")
    try:
        L = np.linalg.cholesky(covariance)
    except np.linalg.LinAlgError:
        raise InputError(f"prior block {', '.join(names)}: covariance is not positive "
                         "definite") from None
    sigma = np.sqrt(np.diag(covariance))
    priors = [make_prior(name, float(v), float(s), "", units)
              for name, v, s in zip(names, value, sigma, strict=True)]
    whitening: np.ndarray = np.linalg.solve(L, np.eye(k))
    return priors, whitening


def block_whitening(blocks: list[np.ndarray]) -> np.ndarray:
    """The block-diagonal matrix of square blocks (the whitening of all priors)."""
    size = sum(b.shape[0] for b in blocks)
    out = np.zeros((size, size))
    start = 0
    for block in blocks:
        stop = start + block.shape[0]
        out[start:stop, start:stop] = block
        start = stop
    return out


def with_prior_blocks(dataset: Any, blocks: list[JsonObject]) -> Any:
    """A copy of `dataset` whose `prior_blocks` also hold these (added to the file's)."""
    if not blocks:
        return dataset
    extra = dict(dataset.extra_fields)
    extra["prior_blocks"] = list(extra.get("prior_blocks") or []) + [dict(b) for b in blocks]
    return dataclasses.replace(dataset, extra_fields=extra)


def problem_constraints(problem: Any) -> Constraints | None:
    """The constraints of a built problem (from its dataset), or None."""
    return constraints_for(problem.dataset.extra_fields, tuple(problem.layout.names),
                           tuple(problem.layout.units))


def with_constraints(dataset: Any, priors: Iterable[str] | Mapping[str, Any] | None = None,
                     hold: Iterable[str] | str | None = None) -> Any:
    """A copy of `dataset` whose `priors`/`hold` also hold these (added to the file's)."""
    if not priors and not hold:
        return dataset
    extra = dict(dataset.extra_fields)
    if priors:
        old = _prior_entries(extra.get("priors"))
        new = _prior_entries(priors if not isinstance(priors, str) else [priors])
        extra["priors"] = _flatten([e if isinstance(e, str) else {e[0]: e[1]}
                                    for e in old + new])
    if hold:
        extra["hold"] = hold_names(extra.get("hold")) + hold_names(
            [hold] if isinstance(hold, str) else list(hold))
    return dataclasses.replace(dataset, extra_fields=extra)


def _flatten(entries: list[Any]) -> list[str]:
    """Strings stay a list; mappings are turned into strings in SI (so both mix)."""
    out: list[str] = []
    for e in entries:
        if isinstance(e, str):
            out.append(e)
        else:
            for name, spec in e.items():
                unit = spec.get("unit", "") if isinstance(spec, Mapping) else ""
                out.append(f"{name}={float(spec['value'])!r}+-{float(spec['sigma'])!r}{unit}")
    return out


def analyse_with_constraints(jacobian: np.ndarray, names: tuple[str, ...],
                             units: tuple[str, ...], constraints: Constraints | None,
                             frames: Collection[str] | None = None) -> tuple[Any, list[str]]:
    """Identifiability of the whitened Jacobian (N*m, P) with the prior rows stacked under it
    and the held columns left out (held parameters count as fixed), and a note for every
    direction the measurements alone cannot see but the priors make identifiable."""
    from hostpc.fitting.identifiability import Identifiability, analyse

    if constraints is None:
        return analyse(jacobian, names, units, frames=frames), []
    prior_rows = constraints.jacobian(len(names))
    keep = ~constraints.held
    kept_names = tuple(n for n, k in zip(names, keep, strict=True) if k)
    kept_units = tuple(u for u, k in zip(units, keep, strict=True) if k)
    with_priors = analyse(np.vstack([jacobian, prior_rows])[:, keep], kept_names, kept_units,
                          frames=frames)
    notes: list[str] = []
    if constraints.index.size:
        without = analyse(jacobian[:, keep], kept_names, kept_units, frames=frames)
        resolved = len(without.null_directions) - len(with_priors.null_directions)
        if resolved > 0:
            named = ", ".join(sorted({p.name for p in constraints.priors}))
            notes.append(f"the prior(s) on {named} make {resolved} direction(s) identifiable "
                         "that the measurements alone cannot separate")
    fixed = constraints.held.copy()
    fixed[np.flatnonzero(keep)] = with_priors.fixed
    return Identifiability(with_priors.rank, with_priors.singular_values,
                           with_priors.condition_number, fixed,
                           with_priors.null_directions), notes
