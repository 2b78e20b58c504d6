"""The report's plots, each returned as a ``data:image/png;base64,...`` URI.

matplotlib through its object API with the Agg canvas only (no pyplot, no global backend
switch), so rendering works headless and leaves the caller's matplotlib state alone.
Lengths are shown in mm (docs/conventions.md: mm only at the edges).
"""

from __future__ import annotations

import base64
import io
import math
from collections.abc import Sequence
from typing import Literal

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from hostpc.diagnostics import Diagnosis
from hostpc.diagnostics.residual_analysis import VariablePattern
from hostpc.fitting.identifiability import RELATIVE_RANK_TOLERANCE

MM = 1e3
AXIS_NAMES = {3: ("x", "y", "z"), 1: ("distance",)}
COLOURS = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728")
SIGNIFICANT = "#d62728"
PLAIN = "#7f7f7f"


def _figure(width: float, height: float,
            layout: Literal["constrained"] | None = "constrained") -> Figure:
    """A figure on its own Agg canvas. Constrained layout is slow with many axes: the grid
    of small panels places its axes itself (layout None)."""
    figure = Figure(figsize=(width, height), dpi=100, layout=layout)
    FigureCanvasAgg(figure)
    return figure


def to_data_uri(figure: Figure) -> str:
    """PNG of the figure as a data URI."""
    buffer = io.BytesIO()
    figure.savefig(buffer, format="png", dpi=90)
    return "data:image/png;base64," + base64.b64encode(buffer.getvalue()).decode("ascii")


def _axis_names(m: int) -> Sequence[str]:
    return AXIS_NAMES.get(m, tuple(f"r{k + 1}" for k in range(m)))


def model_vs_measurement(diagnosis: Diagnosis) -> str:
    """Measured against predicted (per component), and the residual of every sample."""
    fit = diagnosis.fit
    measured = fit.problem.measured
    predicted = measured - fit.residuals_raw
    m = measured.shape[1]
    names = _axis_names(m)
    figure = _figure(11, 3.6)
    left, right = figure.subplots(1, 2, width_ratios=(1, 2))
    for k in range(m):
        left.plot(predicted[:, k] * MM, measured[:, k] * MM, ".", ms=4, color=COLOURS[k % 4],
                  label=names[k])
    low = float(min(measured.min(), predicted.min())) * MM
    high = float(max(measured.max(), predicted.max())) * MM
    left.plot([low, high], [low, high], "-", color="black", lw=0.8)
    left.set_xlabel("model prediction [mm]")
    left.set_ylabel("measurement [mm]")
    left.set_title("model vs measurement")
    left.legend(fontsize=8)
    index = np.arange(measured.shape[0])
    for k in range(m):
        right.plot(index, fit.residuals_raw[:, k] * MM, ".-", lw=0.5, ms=3,
                   color=COLOURS[k % 4], label=f"residual {names[k]}")
    held = diagnosis.check.held_out
    if held is not None:
        right.plot(index, held.norms * MM, "k.", ms=3, label="held-out |residual|")
    right.axhline(0.0, color="black", lw=0.6)
    right.set_xlabel("sample")
    right.set_ylabel("measured - predicted [mm]")
    right.set_title("residual per sample")
    right.legend(fontsize=8, ncols=2)
    return to_data_uri(figure)


def _inliers(diagnosis: Diagnosis) -> np.ndarray:
    """(N,) True for the samples that are not outliers (outliers would set every scale)."""
    keep = np.ones(diagnosis.fit.residuals_raw.shape[0], dtype=bool)
    keep[list(diagnosis.check.excluded)] = False
    return keep


def _limit(values: np.ndarray, floor: float) -> float:
    """A symmetric axis limit for the values, at least ``floor``."""
    return max(floor, float(np.max(np.abs(values))) if values.size else floor)


def whitened_histogram(diagnosis: Diagnosis) -> str:
    """Whitened residuals against the unit normal they should follow (the range is set by
    the samples that are not outliers; outliers fall outside it)."""
    values = diagnosis.fit.residuals_whitened.ravel()
    figure = _figure(5.5, 3.6)
    axes = figure.subplots()
    limit = _limit(diagnosis.fit.residuals_whitened[_inliers(diagnosis)], 4.0)
    axes.hist(values, bins=40, range=(-limit, limit), density=True, color="#9ecae1",
              label="whitened residuals")
    grid = np.linspace(-limit, limit, 200)
    axes.plot(grid, np.exp(-grid**2 / 2) / math.sqrt(2 * math.pi), "k-", lw=1,
              label="N(0, 1)")
    axes.set_xlabel("whitened residual [sigma]")
    axes.set_title(f"whitened residuals (chi2/dof {diagnosis.chi2_dof:.3f})")
    axes.legend(fontsize=8)
    return to_data_uri(figure)


def _pattern_panel(axes, pattern: VariablePattern, values: np.ndarray, whitened: np.ndarray,
                   names: Sequence[str]) -> None:  # type: ignore[no-untyped-def]
    for k in range(whitened.shape[1]):
        axes.plot(values, whitened[:, k], ".", ms=2, alpha=0.35, color=COLOURS[k % 4])
        axes.plot(pattern.centres, pattern.mean_whitened[:, k], "o-", ms=3, lw=1.2,
                  color=COLOURS[k % 4], label=names[k])
    axes.axhline(0.0, color="black", lw=0.5)
    colour = SIGNIFICANT if pattern.significant else "black"
    axes.set_title(f"{pattern.variable}  p={pattern.p_value:.2g}", fontsize=9, color=colour)
    axes.tick_params(labelsize=7)


def residuals_vs_variables(diagnosis: Diagnosis, variables: dict[str, np.ndarray]) -> str:
    """The whitened residual components against every variable, with binned means (whitened,
    so every axis and sample counts by its own noise: a pattern stands out of +-1)."""
    patterns = sorted(diagnosis.residuals.patterns, key=lambda p: p.variable)
    whitened = diagnosis.fit.residuals_whitened
    names = _axis_names(whitened.shape[1])
    columns = 5
    rows = max(1, math.ceil(len(patterns) / columns))
    height = 2.2 * rows + 0.6
    figure = _figure(13, height, layout=None)
    figure.subplots_adjust(left=0.05, right=0.99, bottom=0.35 / height, top=1 - 0.6 / height,
                           hspace=0.45, wspace=0.25)
    grid = figure.subplots(rows, columns, squeeze=False, sharey=True)
    for axes, pattern in zip(grid.ravel(), patterns, strict=False):
        _pattern_panel(axes, pattern, variables[pattern.variable], whitened, names)
    for axes in grid.ravel()[len(patterns):]:
        axes.set_visible(False)
    if patterns:
        grid[0, 0].legend(fontsize=7)
        grid[0, 0].set_ylabel("whitened residual [sigma]", fontsize=8)
        limit = _limit(whitened[_inliers(diagnosis)], 3.0)
        grid[0, 0].set_ylim(-limit, limit)
    figure.suptitle("whitened residuals against every variable (dots: samples; lines: binned "
                    "means; red title: significant)", fontsize=10)
    return to_data_uri(figure)


def _barh(axes, labels: Sequence[str], values: Sequence[float], flags: Sequence[bool]
          ) -> None:  # type: ignore[no-untyped-def]
    positions = np.arange(len(labels))[::-1]
    colours = [SIGNIFICANT if f else PLAIN for f in flags]
    axes.barh(positions, values, color=colours)
    axes.set_yticks(positions, labels, fontsize=8)
    axes.axvline(0.0, color="black", lw=0.6)


def candidate_ranking(diagnosis: Diagnosis) -> str:
    """Delta BIC of every candidate effect (red: significant)."""
    candidates = diagnosis.candidates
    figure = _figure(5.5, 0.45 * max(len(candidates), 2) + 1.2)
    axes = figure.subplots()
    if candidates:
        _barh(axes, [c.effect if c.testable else f"{c.effect} (not testable)"
                     for c in candidates],
              [np.nan if c.delta_bic is None else c.delta_bic for c in candidates],
              [c.significant for c in candidates])
    axes.set_xlabel("delta BIC when added (negative: better)")
    axes.set_title("candidate effects")
    return to_data_uri(figure)


def interaction_ranking(diagnosis: Diagnosis, top: int = 15) -> str:
    """The strongest "parameter varies with variable" scores, with the significance line."""
    shown = diagnosis.interactions[:top]
    figure = _figure(6.5, 0.3 * max(len(shown), 2) + 1.2)
    axes = figure.subplots()
    if shown:
        _barh(axes, [i.sentence for i in shown], [i.score for i in shown],
              [i.significant for i in shown])
        n_tests = max(diagnosis.check.n_interaction_tests, 1)
        axes.axvline(-math.log10(diagnosis.alpha / n_tests), color=SIGNIFICANT, ls="--",
                     lw=0.8, label="significance")
        axes.legend(fontsize=8)
    axes.set_xlabel("score = -log10(p)")
    axes.set_title("which parameter varies with which variable")
    return to_data_uri(figure)


def ladder_chart(diagnosis: Diagnosis) -> str:
    """Per ladder step: in-sample and held-out RMS against the noise level (mm), the held-out
    max (mm), and the whitened held-out RMS and chi2/dof against 1 (the stated noise)."""
    steps = diagnosis.ladder or ()
    figure = _figure(12, 3.6)
    rms_axes, max_axes, sigma_axes = figure.subplots(1, 3)
    x = np.arange(len(steps))
    labels = [f"{s.added or 'current'}\n({'adequate' if s.adequate else 'NOT adequate'})"
              for s in steps]

    def held(values: list[float | None]) -> list[float]:
        return [np.nan if v is None else v for v in values]

    rms_axes.plot(x, [s.rms * MM for s in steps], "o-", label="in-sample RMS")
    rms_axes.plot(x, [v * MM for v in held([s.cv_rms for s in steps])], "s-",
                  label="held-out RMS")
    rms_axes.axhline(diagnosis.check.adequacy.expected_noise_rms * MM, color="black", ls=":",
                     lw=1, label="noise level (stated)")
    rms_axes.set_ylabel("[mm]")
    rms_axes.set_title("RMS of the residual norm")
    max_axes.plot(x, [s.max * MM for s in steps], "o-", label="in-sample max")
    max_axes.plot(x, [v * MM for v in held([s.cv_max for s in steps])], "^-",
                  label="held-out max")
    max_axes.set_ylabel("[mm]")
    max_axes.set_title("largest residual")
    sigma_axes.plot(x, held([s.cv_whitened_rms for s in steps]), "s-",
                    label="held-out, whitened RMS")
    sigma_axes.plot(x, [s.chi2_dof for s in steps], "o-", label="chi2/dof")
    sigma_axes.axhline(1.0, color="black", ls=":", lw=1, label="the stated noise")
    sigma_axes.set_title("in units of the stated noise")
    for axes in (rms_axes, max_axes, sigma_axes):
        axes.set_xticks(x, labels, fontsize=8)
        axes.set_xlim(-0.4, max(len(steps) - 0.6, 0.4))
        axes.legend(fontsize=8)
    return to_data_uri(figure)


def correlation_matrix(diagnosis: Diagnosis) -> str:
    """Correlations of the free parameters."""
    fit = diagnosis.fit
    free = np.flatnonzero(~fit.fixed)
    std = fit.std[free]
    cov = fit.covariance[np.ix_(free, free)]
    rho = cov / np.maximum(np.outer(std, std), 1e-300)
    size = max(4.0, 0.22 * free.size + 2.0)
    figure = _figure(size + 1.0, size)
    axes = figure.subplots()
    image = axes.imshow(rho, vmin=-1, vmax=1, cmap="RdBu_r")
    labels = [fit.names[k] for k in free]
    axes.set_xticks(range(len(labels)), labels, rotation=90, fontsize=6)
    axes.set_yticks(range(len(labels)), labels, fontsize=6)
    figure.colorbar(image, ax=axes, shrink=0.8)
    axes.set_title("parameter correlations")
    return to_data_uri(figure)


def singular_values(diagnosis: Diagnosis) -> str:
    """Relative singular values of the normalised Jacobian (identifiability)."""
    values = np.asarray(diagnosis.fit.singular_values, dtype=float)
    figure = _figure(5.5, 3.2)
    axes = figure.subplots()
    shown = np.maximum(values, 1e-18)
    axes.semilogy(np.arange(1, shown.size + 1), shown, "o-", ms=4)
    axes.axhline(RELATIVE_RANK_TOLERANCE, color=SIGNIFICANT, ls="--", lw=0.8,
                 label="rank tolerance")
    axes.set_xlabel("index")
    axes.set_ylabel("relative singular value")
    axes.set_title(f"identifiability: rank {diagnosis.fit.rank} of {values.size}")
    axes.legend(fontsize=8)
    return to_data_uri(figure)
