"""Effect sizes: every fitted parameter with its sigma and, for a simulated run, against the
truth the simulator injected.

The simulator (controller_stub, single kinematic chain) writes its hidden effects by joint
(``truth["effects"]``: ``joint_compliance`` rad/(N m), ``backlash`` rad, ``encoder_scale``,
``transmission_harmonic`` rows (sin q, cos q, sin 2q, cos 2q) rad, and
``probe_trigger_latency_s``), with the same definitions as the host's effects of those
names (docs/effects.md), so ``joint_compliance.c2`` is compared with the second entry. An
effect the model has and the simulator did not inject is compared with 0 (its truth): the
simulator has no joint coupling, so ``joint_coupling.k6_5`` is compared with 0 (or with
``effects["joint_coupling"]["k6_5"]`` where a truth names it). ``thermal_expansion.e`` is
compared with the simulator's ``thermal_drift`` (m/s per link length) when the drift is
the same fraction of every nominal link length (``e`` = that fraction per second) and the
fit's driver is the time ``t`` (a drift per kelvin cannot be told from a drift per second).
Parameters without a by-name truth (frames, geometry, kinematic trees) show "not simulated
by name"; joint offsets are compared in the offsets table of a calibration report.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from hostpc.errors import EffectError
from hostpc.fitting import FitResult
from hostpc.model.joint_offsets import is_offset
from hostpc.report.markup import display, escape, table

PER_JOINT = {"joint_compliance": "c", "backlash": "b", "encoder_scale": "s"}
HARMONIC_TERMS = ("sin1", "cos1", "sin2", "cos2")
_JOINT = re.compile(r"^(?P<prefix>[a-z]+)(?P<joint>\d+)$")
_HARMONIC = re.compile(r"^(?P<term>sin1|cos1|sin2|cos2)_q(?P<joint>\d+)$")


def true_value(truth: Mapping[str, Any] | None, name: str, n_joints: int) -> float | None:
    """The injected value of parameter ``name`` (SI), or None where the truth does not
    name it. truth: the simulator's truth dict; n_joints: joints of the fitted robot (a
    truth for another joint count is not compared)."""
    if not truth or "effects" not in truth:
        return None
    if len(truth.get("zero_errors", ())) != n_joints:
        return None
    effects: Mapping[str, Any] = truth["effects"] or {}
    effect, _, local = name.partition(".")
    if effect == "trigger_latency" and local == "latency":
        return float(effects.get("probe_trigger_latency_s", 0.0))
    if effect in PER_JOINT:
        match = _JOINT.match(local)
        if not match or match.group("prefix") != PER_JOINT[effect]:
            return None
        joint = int(match.group("joint")) - 1
        values = effects.get(effect)
        if values is None:
            return 0.0
        return float(values[joint]) if 0 <= joint < len(values) else None
    if effect == "joint_coupling":
        if not re.fullmatch(r"k\d+_\d+", local):
            return None
        coupling = effects.get("joint_coupling") or {}
        return float(coupling.get(local, 0.0))
    if effect == "transmission_harmonic":
        match = _HARMONIC.match(local)
        if not match:
            return None
        joint = int(match.group("joint")) - 1
        rows = effects.get("transmission_harmonic")
        if rows is None:
            return 0.0
        if not 0 <= joint < len(rows):
            return None
        return float(rows[joint][HARMONIC_TERMS.index(match.group("term"))])
    return None


PROPORTIONAL = 0.01
"""A simulated drift counts as thermal expansion when it departs from e * (nominal lengths)
by at most this fraction of its norm."""


def thermal_truth(truth: Mapping[str, Any] | None, fit: FitResult) -> float | None:
    """The true ``thermal_expansion.e`` (1/s) of a simulated run: the simulator's drift of
    the link lengths (``thermal_drift`` d, a in m/s) as one fraction of the nominal lengths;
    0 without a drift; None when the drift is not such a fraction, the fit's driver is a
    recorded temperature, or the truth is another robot's."""
    from hostpc.model.effects.thermal import thermal_driver

    if not truth or "effects" not in truth:
        return None
    chain = fit.problem.chain
    if len(truth.get("zero_errors", ())) != chain.n:
        return None
    try:
        driver, _ = thermal_driver(fit.problem.context)
    except EffectError:  # neither t nor temperature on every sample
        return None
    drift = (truth["effects"] or {}).get("thermal_drift")
    if not drift:
        return 0.0
    if driver != "t":
        return None
    lengths = np.concatenate([np.asarray(chain.d, float), np.asarray(chain.a, float)])
    rates = np.concatenate([np.asarray(drift.get("d", [0.0] * chain.n), float),
                            np.asarray(drift.get("a", [0.0] * chain.n), float)])
    if rates.shape != lengths.shape:
        return None
    e = float(rates @ lengths / max(float(lengths @ lengths), 1e-300))
    departure = float(np.linalg.norm(rates - e * lengths))
    return e if departure <= PROPORTIONAL * max(float(np.linalg.norm(rates)), 1e-300) else None


def sigma_text(std: float | None, unit: str) -> str:
    """A standard deviation in display units, two significant digits."""
    shown = display(std, unit, signed=False)[0]
    return shown if shown == "-" else f"{float(shown):.2g}"


def effect_sizes(fit: FitResult, truth: Mapping[str, Any] | None = None,
                 skip: Sequence[str] = ()) -> str:
    """The effect-size table (HTML) of every parameter of ``fit`` whose effect is not in
    ``skip``: value and sigma in display units (deg, mm, ppm, ms), and with a truth the
    true value and (fitted - true) / sigma, rows beyond 3 sigma marked; then a sentence
    counting them."""
    n_joints = _joints(fit)
    rows, flags = [], []
    compared = within = 0
    for p in fit.parameters.values():
        effect = p.name.partition(".")[0]
        if effect in skip:
            continue
        value, unit = display(p.value, p.unit)
        sigma = "held (unidentifiable)" if p.fixed else sigma_text(p.std, p.unit)
        row = [escape(p.name), value, escape(sigma), escape(unit)]
        flag = False
        if truth is not None:
            true = (thermal_truth(truth, fit) if p.name == "thermal_expansion.e"
                    else true_value(truth, p.name, n_joints))
            if true is None:
                row += ["not simulated by name", "-"]
            else:
                row.append(display(true, p.unit)[0])
                if p.fixed or p.std is None or not (p.std > 0 and math.isfinite(p.std)):
                    row.append("-")
                else:
                    z = (p.value - true) / p.std
                    compared += 1
                    within += abs(z) <= 3.0
                    flag = abs(z) > 3.0
                    row.append(f"{z:+.2f}")
        rows.append(row)
        flags.append(flag)
    if not rows:
        return "<p>The model has no parameters beyond the joint offsets.</p>"
    header = ["parameter", "value", "sigma", "unit"]
    if truth is not None:
        header += ["true (simulation)", "(fitted - true) / sigma"]
    text = table(header, rows, flags=flags, table_id="effect-sizes")
    if truth is not None:
        text += (f'<p class="note">{within} of {compared} parameters with a simulated truth '
                 "are within 3 sigma of it (marked red: beyond).</p>" if compared else
                 '<p class="note">No parameter of this model has a truth the simulator '
                 "names.</p>")
    return text


def _joints(fit: FitResult) -> int:
    """Joints of the fitted robot: its joint-offset parameters (every model has them)."""
    return sum(is_offset(name) for name in fit.names)
