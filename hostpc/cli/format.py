"""Human-readable text of results: mm and degrees (docs/conventions.md: only at the edges)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from hostpc.diagnostics.adequacy import (
    chi2_band,
    chi2_dof_upper,
    chi2_far_below,
    far_below_reason,
    implausible_geometry,
)
from hostpc.display_units import DISPLAY_UNITS
from hostpc.fitting import FitResult
from hostpc.json_object import JsonObject
from hostpc.model.joint_offsets import is_offset

if TYPE_CHECKING:
    from hostpc.diagnostics.robust_kept import KeptSamples

__all__ = ["below_band", "display", "format_fit_summary", "format_parameter_table"]


def below_band(chi2_dof: float, dof: int) -> bool:
    """chi2/dof below the lower edge of its band (``chi2_band``): the stated noise is
    pessimistic, and the sigmas from it too large by 1/sqrt(chi2/dof)."""
    return dof > 0 and math.isfinite(chi2_dof) and chi2_dof < chi2_band(dof)[0]


def display(value: float | None, unit: str) -> tuple[str, str]:
    """(number text, display unit) of an SI value."""
    shown_unit, factor = DISPLAY_UNITS.get(unit, (unit, 1.0))
    if value is None or not math.isfinite(value):
        return "-", shown_unit
    return f"{value * factor:+.4f}", shown_unit


def display_sigma(value: float | None, unit: str) -> str:
    """A sigma's number text in the display unit: four decimals, or three significant digits
    where four decimals would round it to nothing (5e-05 deg, never 0.0000)."""
    text, _ = display(value, unit)
    if value is None or not math.isfinite(value) or value == 0.0:
        return text.lstrip("+")
    shown = abs(value) * DISPLAY_UNITS.get(unit, (unit, 1.0))[1]
    return f"{shown:.3g}" if shown < 0.00995 else text.lstrip("+")


def format_parameter_table(result: FitResult, scaled: np.ndarray | None = None,
                           jackknife: np.ndarray | None = None) -> list[str]:
    """The parameter table; `scaled` / `jackknife`: (P,) further sigma columns (the sigmas
    times sqrt(chi2/dof), the leave-one-pose-out jackknife; hostpc.fitting.resampling)."""
    extra = [(name, values) for name, values in
             (("x sqrt(chi2/dof)", scaled), ("jackknife", jackknife)) if values is not None]
    lines = [f"  {'parameter':<32} {'value':>12} {'+/- sigma':>11}"
             + "".join(f" {name:>16}" for name, _ in extra) + "  unit"]
    for k, p in enumerate(result.parameters.values()):
        value, unit = display(p.value, p.unit)
        if p.fixed:
            sigma = "  (fixed)"
            columns = "".join(f" {'':>16}" for _ in extra)
        else:
            sigma = display_sigma(p.std, p.unit)
            columns = "".join(f" {display_sigma(float(v[k]), p.unit):>16}" for _, v in extra)
        lines.append(f"  {p.name:<32} {value:>12} {sigma:>11}{columns}  {unit}")
    return lines


@dataclass(frozen=True)
class ModelAdequacy:
    """Whether the converged model explains the data: its chi2/dof against the chi-square
    band (hostpc.diagnostics.adequacy.chi2_dof_upper, the push guard's rule). A solver
    that converged far outside the band has found the best of a wrong model.
    chi2_dof / chi2_dof_upper: None where not finite; explains_data: None with no dof to
    judge; next_command: the diagnosis to run when it does not explain the data."""

    chi2_dof: float | None
    chi2_dof_upper: float | None
    explains_data: bool | None
    next_command: str | None
    kept: KeptSamples | None = None
    """A robust-loss fit judged on the samples its loss keeps (chi2_dof and its band are
    then theirs; hostpc.diagnostics.robust_kept), else None."""

    def to_json(self) -> JsonObject:
        """`hostpc fit --json`'s "model_adequacy" block."""
        block: JsonObject = {"chi2_dof": self.chi2_dof, "chi2_dof_upper": self.chi2_dof_upper,
                             "explains_data": self.explains_data, "next": self.next_command}
        if self.kept is not None:
            block["kept_samples"] = self.kept.to_json()
        return block


def model_adequacy(result: FitResult, source: str = "DATASET", options: str = ""
                   ) -> ModelAdequacy:
    """The fit's `ModelAdequacy`; `source` names the dataset in the next command and
    `options` are the options that define its data (hostpc.cli.robot_options.data_options: --robot,
    --base-link, --tip-link, --plugin), carried into it."""
    from hostpc.diagnostics.robust_kept import kept_samples  # fit's: diagnose needs none

    kept = kept_samples(result)  # a robust loss: judged on the samples it keeps
    dof, chi2_dof = (result.dof, result.chi2_dof) if kept is None else (kept.dof, kept.chi2_dof)
    band = chi2_dof_upper(dof)
    judged = math.isfinite(band) and math.isfinite(chi2_dof)
    explains = (chi2_dof <= band) if judged else None
    return ModelAdequacy(
        chi2_dof=chi2_dof if math.isfinite(chi2_dof) else None,
        chi2_dof_upper=band if math.isfinite(band) else None, explains_data=explains,
        next_command=(None if explains is not False
                      else f"hostpc diagnose {source}{options} --ladder"), kept=kept)


UNITS_HINT_NOISE_RATIO = 100.0
"""A fit whose residuals are this many times the stated noise (sqrt(chi2/dof)) or more
points at the data before the model: numbers in another unit than `units` says."""


def _converged_line(result: FitResult, source: str, options: str = "",
                    units_hint: str = "") -> str:
    """Never a plain "converged: yes" for a model that does not explain the data; a fit
    that did not converge says so with the next step; `units_hint`: what the numbers say of
    the declared length unit (hostpc.cli.units_hint)."""
    how = f"({result.message}, {result.iterations} iterations)"
    if not result.converged:
        ratio = math.sqrt(result.chi2_dof) if result.chi2_dof >= 0 else math.nan
        hint = units_hint or "check the dataset's `units`"
        units = (f"the residuals are {ratio:.3g} times the stated noise: {hint}; "
                 if ratio >= UNITS_HINT_NOISE_RATIO else "")
        next_command = (model_adequacy(result, source or "DATASET", options).next_command
                        or f"hostpc diagnose {source or 'DATASET'}{options}")
        return (f"  converged: NO {how}: the values below are not a fit (hostpc push "
                f"refuses it); {units}next: {next_command}")
    if result.dof <= 0:
        n_samples, m = result.residuals_raw.shape
        # a sample adds m measured numbers: this many more give a positive dof
        more = max(1, math.ceil((1 - result.dof) / m))
        return (f"  converged (solver) {how}, but with {result.dof} degrees of freedom: the "
                f"{int(np.count_nonzero(~result.fixed))} free parameters pass exactly through "
                f"the {n_samples * m} measured numbers, so nothing tests the model or the "
                "noise and the sigmas assume both; measure more poses: at least "
                f"{more} more sample{'s' if more > 1 else ''} for one degree of freedom ({m} "
                "numbers each), several times that to test the model")
    adequacy = model_adequacy(result, source or "DATASET", options)
    kept = adequacy.kept
    if adequacy.explains_data is False and adequacy.chi2_dof_upper is not None:
        chi2_dof = result.chi2_dof if kept is None else kept.chi2_dof
        ratio = chi2_dof / adequacy.chi2_dof_upper  # > 1; said, never "far" at 1.001
        by = f"{ratio:.3g} times" if ratio >= 2 else f"by {ratio - 1:.2%}"
        units = (f"the residuals are {math.sqrt(result.chi2_dof):.3g} times the stated "
                 f"noise: {units_hint}; " if units_hint and math.sqrt(result.chi2_dof)
                 >= UNITS_HINT_NOISE_RATIO else "")
        over = "" if kept is None else f" ({kept.sentence()})"
        return (f"  converged (solver) {how}, but the model does not explain the data: "
                f"chi2/dof {chi2_dof:.4g} above its band "
                f"{adequacy.chi2_dof_upper:.4g} ({by}){over}; {units}next: "
                f"{adequacy.next_command}")
    if chi2_far_below(result.chi2, result.dof):  # a unit slip the geometry absorbed
        far_below = far_below_reason(result.chi2_dof, chi2_band(result.dof), result.dof)
        return f"  converged (solver) {how}, but {far_below}"
    return f"  converged: yes {how}" + ("" if kept is None else f"; {kept.sentence()}")


def format_fit_summary(result: FitResult, source: str = "",
                       scaled: np.ndarray | None = None,
                       jackknife: np.ndarray | None = None, options: str = "",
                       units_hint: str = "") -> str:
    """The fit as text; `scaled` / `jackknife`: further sigma columns (see
    format_parameter_table), with a line that says which sigma is which; `options`: as for
    model_adequacy; `units_hint`: as for _converged_line."""
    n_samples = result.residuals_raw.shape[0]
    head = f"fit of {source}" if source else "fit"
    lines = [
        f"{head}: method {result.problem.method}, {n_samples} samples, "
        f"effects {', '.join(result.problem.effect_names)}",
        _converged_line(result, source, options, units_hint),
        f"  residual RMS {result.rms * 1e3:.4f} mm, max {result.max * 1e3:.4f} mm, "
        f"chi2/dof {result.chi2_dof:.3f} (dof {result.dof})"
        + (f", {result.cv_folds}-fold cross-validated RMS {result.cv_rms * 1e3:.4f} mm"
           if result.cv_rms is not None else ""),
        f"  Jacobian rank {result.rank} of {len(result.names)}, "
        f"condition number {result.condition_number:.3g}",
        "",
        *format_parameter_table(result, scaled, jackknife),
    ]
    if scaled is not None or jackknife is not None:
        lines += ["", "  sigma: from the stated noise of the samples"]
        if scaled is not None and below_band(result.chi2_dof, result.dof):
            lines.append(f"  x sqrt(chi2/dof): scaled by the measured noise "
                         f"({math.sqrt(result.chi2_dof):.2f}x; chi2/dof is below its band "
                         f"{chi2_band(result.dof)[0]:.3f}: the stated noise is pessimistic, "
                         "the sigmas from it too large; these are the ones the data shows)")
        elif scaled is not None:
            lines.append(f"  x sqrt(chi2/dof): scaled by the measured noise "
                         f"({math.sqrt(result.chi2_dof):.2f}x; chi2/dof is above its band: "
                         "the stated noise is too small, or the model misses an effect)")
        if jackknife is not None:
            lines.append("  jackknife: the spread of the fits leaving one pose out (no noise "
                         "model assumed)")
    implausible = implausible_geometry(result)
    if implausible is not None:
        lines += ["", f"warning: {implausible}"]
    if result.unidentifiable:
        lines += ["", "identifiability warnings:"]
        lines += [f"  - {d.description}" for d in result.unidentifiable]
    if result.correlations:
        lines += ["", "strong correlations (|rho| > 0.9):"]
        lines += [f"  - {a} ~ {b}: {rho:+.3f}" for a, b, rho in result.correlations[:10]]
        if len(result.correlations) > 10:
            lines.append(f"  ... and {len(result.correlations) - 10} more")
    lines += repeated_lines(result)
    largest: dict[str, float] = {}  # per unit: a revolute joint's angle, a prismatic one's length
    for p in result.parameters.values():
        if is_offset(p.name):
            largest[p.unit] = max(largest.get(p.unit, 0.0), abs(p.value))
    if largest:
        lines += ["", "largest joint offset correction: " + ", ".join(
            "{} {}".format(*display(value, unit)).lstrip("+")
            for unit, value in largest.items())]
    return "\n".join(lines)


def repeated_lines(result: FitResult) -> list[str]:
    """A warning when samples repeat another one exactly (copied rows): the fit counts
    each as a new measurement."""
    from hostpc.fitting.folds import repeated_samples

    pairs = repeated_samples(result.problem.dataset.samples, result.problem.measured)
    if not pairs:
        return []
    shown = ", ".join(f"#{i} = #{j}" for i, j in pairs[:5]) + (
        f", and {len(pairs) - 5} more" if len(pairs) > 5 else "")
    counted = "1 sample repeats" if len(pairs) == 1 else f"{len(pairs)} samples repeat"
    return ["", f"warning: {counted} another sample exactly ({shown}): the "
            "fit counts each as a new measurement, so its dof, chi2/dof and every sigma treat "
            "copies as data; remove the copied rows (a real repeat of a pose differs by its "
            "noise)"]
