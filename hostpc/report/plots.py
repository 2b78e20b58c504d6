"""The report's figures, each returned as one inline ``<svg>`` element (see svg.py for why
not matplotlib). Lengths are shown in mm (docs/conventions.md: mm only at the edges).

Lighter for big datasets: a scatter draws at most ``MAX_POINTS`` samples (an even stride
through them); lines, binned means and histograms always use every sample.
"""

from __future__ import annotations

import html
import math
from collections.abc import Sequence

import numpy as np

from hostpc.diagnostics import Diagnosis
from hostpc.fitting.identifiability import RELATIVE_RANK_TOLERANCE
from hostpc.report.svg import Axes, Canvas, limits

MM = 1e3
AXIS_NAMES = {3: ("x", "y", "z"), 1: ("distance",)}
COLOURS = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728")
SIGNIFICANT = "#d62728"
PLAIN = "#7f7f7f"
MAX_POINTS = 1500


def _axis_names(m: int) -> Sequence[str]:
    return AXIS_NAMES.get(m, tuple(f"r{k + 1}" for k in range(m)))


def _stride(n: int, budget: int = MAX_POINTS) -> slice:
    """Every k-th sample so that at most ``budget`` are drawn."""
    return slice(None, None, max(1, math.ceil(n / budget)))


def _inliers(diagnosis: Diagnosis) -> np.ndarray:
    """(N,) True for the samples that are not outliers (outliers would set every scale)."""
    keep = np.ones(diagnosis.fit.residuals_raw.shape[0], dtype=bool)
    keep[list(diagnosis.check.excluded)] = False
    return keep


def _limit(values: np.ndarray, floor: float) -> float:
    """A symmetric axis limit for the values, at least ``floor``."""
    finite = values[np.isfinite(values)]
    return max(floor, float(np.max(np.abs(finite))) if finite.size else floor)


def model_vs_measurement(diagnosis: Diagnosis) -> str:
    """Measured against predicted (per component), and the residual of every sample."""
    fit = diagnosis.fit
    measured = fit.problem.measured * MM
    residuals = fit.residuals_raw * MM
    predicted = measured - residuals
    n, m = measured.shape
    names = _axis_names(m)
    canvas = Canvas(1100, 340, "model vs measurement, and the residual per sample")
    low, high = limits(np.concatenate([measured.ravel(), predicted.ravel()]))
    left = canvas.axes(60, 28, 300, 260, (low, high), (low, high))
    every = _stride(n)
    for k in range(m):
        left.points(predicted[every, k], measured[every, k], COLOURS[k % 4], 3.5)
    left.line([low, high], [low, high], "black", 0.8)
    left.frame("model vs measurement", "model prediction [mm]", "measurement [mm]")
    left.legend([(names[k], COLOURS[k % 4]) for k in range(m)], corner="left")
    index = np.arange(n)
    held = diagnosis.check.held_out
    held_norms = held.norms * MM if held is not None else np.zeros(0)
    right = canvas.axes(440, 28, 640, 260, (-0.5, n - 0.5),
                        limits(np.concatenate([residuals.ravel(), held_norms]), include=[0.0]))
    for k in range(m):
        right.line(index, residuals[:, k], COLOURS[k % 4], 0.6, markers=2.5 if n <= 400 else 0)
    if held is not None:
        right.points(index, held_norms, "black", 3.0)
    right.hline(0.0, "black", 0.6)
    right.frame("residual per sample", "sample", "measured - predicted [mm]")
    right.legend([(f"residual {names[k]}", COLOURS[k % 4]) for k in range(m)]
                 + ([("held-out |residual|", "black")] if held is not None else []))
    return canvas.render()


def whitened_histogram(diagnosis: Diagnosis) -> str:
    """Whitened residuals against the unit normal they should follow (the range is set by
    the samples that are not outliers; outliers fall outside it)."""
    values = diagnosis.fit.residuals_whitened.ravel()
    limit = _limit(diagnosis.fit.residuals_whitened[_inliers(diagnosis)], 4.0)
    counts, edges = np.histogram(values, bins=40, range=(-limit, limit))
    density = counts / max(values.size, 1) / (edges[1] - edges[0])
    grid = np.linspace(-limit, limit, 121)
    normal = np.exp(-grid**2 / 2) / math.sqrt(2 * math.pi)
    canvas = Canvas(520, 320, "histogram of the whitened residuals against N(0, 1)")
    axes = canvas.axes(55, 28, 440, 245, (-limit, limit),
                       (0.0, max(float(density.max(initial=0.0)), 0.4) * 1.08))
    axes.rects(edges[:-1], edges[1:], np.zeros_like(density), density,
               ["#9ecae1"] * density.size)
    axes.line(grid, normal, "black", 1.2)
    axes.frame(f"whitened residuals (chi2/dof {diagnosis.chi2_dof:.3f})",
               "whitened residual [sigma]", "density")
    axes.legend([("whitened residuals", "#9ecae1"), ("N(0, 1)", "black")])
    return canvas.render()


def residuals_vs_variables(diagnosis: Diagnosis, variables: dict[str, np.ndarray]) -> str:
    """The whitened residual components against every variable, with binned means (whitened,
    so every axis and sample counts by its own noise: a pattern stands out of +-1)."""
    patterns = sorted(diagnosis.residuals.patterns, key=lambda p: p.variable)
    whitened = diagnosis.fit.residuals_whitened
    n, m = whitened.shape
    names = _axis_names(m)
    columns = 5
    rows = max(1, math.ceil(len(patterns) / columns))
    cell_w, cell_h = 236, 170
    canvas = Canvas(columns * cell_w + 60, rows * cell_h + 40,
                    "whitened residuals against every variable with binned means")
    canvas.text(30 + columns * cell_w / 2, 16, "whitened residuals against every variable "
                "(dots: samples; lines: binned means; red title: significant)", 12)
    limit = _limit(whitened[_inliers(diagnosis)], 3.0)
    every = _stride(n, MAX_POINTS // max(len(patterns), 1) + 50)
    for k, pattern in enumerate(patterns):
        row, column = divmod(k, columns)
        values = np.asarray(variables[pattern.variable], dtype=float)
        # a group label (pattern.levels): one column per level code, named by the level
        xlim = ((float(np.nanmin(pattern.centres)) - 0.5, float(np.nanmax(pattern.centres))
                 + 0.5) if pattern.levels else limits(values))
        axes: Axes = canvas.axes(60 + column * cell_w, 50 + row * cell_h, cell_w - 30,
                                 cell_h - 55, xlim, (-limit, limit))
        for c in range(m):
            axes.points(values[every], whitened[every, c], COLOURS[c % 4], 2.5, 0.4)
            axes.line(pattern.centres, pattern.mean_whitened[:, c], COLOURS[c % 4], 1.4,
                      markers=4.0)
        axes.hline(0.0, "black", 0.5)
        axes.frame(f"{pattern.variable}  p={pattern.p_value:.2g}",
                   title_colour=SIGNIFICANT if pattern.significant else "black",
                   xticks=not pattern.levels, yticks=column == 0, font=10,
                   ylabel="whitened [sigma]" if column == 0 else "")
        if pattern.levels:
            axes.level_labels(pattern.levels, pattern.centres)
        if k == 0:
            axes.legend([(names[c], COLOURS[c % 4]) for c in range(m)])
    return canvas.render()


def _barh(label: str, title: str, xlabel: str, labels: Sequence[str],
          values: Sequence[float], flags: Sequence[bool], line: float | None = None) -> str:
    """Horizontal bars, first label on top (red: significant); ``line``: a dashed marker."""
    width_labels = min(360, 40 + 6.2 * max((len(s) for s in labels), default=10))
    height = 24 * max(len(labels), 2) + 80
    canvas = Canvas(width_labels + 330, height, label)
    data = np.asarray(values, dtype=float)
    xlim = limits(data, include=[0.0] + ([line] if line is not None else []))
    positions = np.arange(len(labels))[::-1].astype(float)
    axes = canvas.axes(width_labels, 30, 300, height - 75, xlim, (-0.6, len(labels) - 0.4))
    colours = [SIGNIFICANT if f else PLAIN for f in flags]
    axes.rects(np.zeros_like(data), data, positions - 0.35, positions + 0.35, colours)
    axes.vline(0.0, "black", 0.6)
    axes.frame(title, xlabel, yticks=False)
    if line is not None:
        axes.vline(line, SIGNIFICANT, 1.0, "4 3")
        axes.legend([("significance", SIGNIFICANT)], corner="bottom right")
    axes.category_labels(labels, positions)
    return canvas.render()


def candidate_ranking(diagnosis: Diagnosis) -> str:
    """Delta BIC of every candidate effect (red: significant)."""
    candidates = diagnosis.candidates
    return _barh("candidate effects by delta BIC", "candidate effects",
                 "delta BIC when added (negative: better)",
                 [c.effect if c.testable else f"{c.effect} (not testable)" for c in candidates],
                 [np.nan if c.delta_bic is None else c.delta_bic for c in candidates],
                 [c.significant for c in candidates])


def interaction_ranking(diagnosis: Diagnosis, top: int = 15) -> str:
    """The strongest "parameter varies with variable" scores, with the significance line."""
    shown = diagnosis.interactions[:top]
    n_tests = max(diagnosis.check.n_interaction_tests, 1)
    return _barh("parameter varies with variable scores",
                 "which parameter varies with which variable",
                 "score = -log10(p)", [i.sentence for i in shown], [i.score for i in shown],
                 [i.significant for i in shown],
                 -math.log10(diagnosis.alpha / n_tests) if shown else None)


def ladder_chart(diagnosis: Diagnosis) -> str:
    """Per ladder step: in-sample and held-out RMS against the noise level (mm), the held-out
    max (mm), and the whitened held-out RMS and chi2/dof against 1 (the stated noise)."""
    steps = diagnosis.ladder or ()
    x = np.arange(len(steps), dtype=float)

    def held(values: Sequence[float | None], scale: float = 1.0) -> np.ndarray:
        return np.array([np.nan if v is None else v * scale for v in values], dtype=float)

    noise = diagnosis.check.adequacy.expected_noise_rms * MM
    panels = [
        ("RMS of the residual norm [mm]",
         [("in-sample RMS", np.array([s.rms * MM for s in steps])),
          ("held-out RMS", held([s.cv_rms for s in steps], MM))], noise, "noise (stated)"),
        ("largest residual [mm]",
         [("in-sample max", np.array([s.max * MM for s in steps])),
          ("held-out max", held([s.cv_max for s in steps], MM))], None, ""),
        ("in units of the stated noise",
         [("held-out, whitened RMS", held([s.cv_whitened_rms for s in steps])),
          ("chi2/dof", np.array([s.chi2_dof for s in steps]))], 1.0, "the stated noise"),
    ]
    canvas = Canvas(1140, 330, "ladder: error at each step")
    for k, (title, series, reference, reference_label) in enumerate(panels):
        everything = np.concatenate([v for _, v in series])
        low, high = limits(everything, 0.1, include=[] if reference is None else [reference])
        ylim = (low, high + 0.45 * (high - low))  # headroom: the legend sits above the data
        axes = canvas.axes(60 + k * 375, 28, 320, 230, (-0.4, max(len(steps) - 0.6, 0.4)), ylim)
        entries = []
        for c, (name, values) in enumerate(series):
            axes.line(x, values, COLOURS[c], 1.4, markers=6.0)
            entries.append((name, COLOURS[c]))
        if reference is not None:
            axes.hline(reference, "black", 1.0, "2 3")
            entries.append((reference_label, "black"))
        axes.frame(title, xticks=False)
        axes.legend(entries)
        for step, position in zip(steps, axes.px(x), strict=True):
            verdict = "adequate" if step.adequate else "NOT adequate"
            canvas.text(axes.left + position, axes.top + axes.height + 14,
                        step.change or "current", 9)
            canvas.text(axes.left + position, axes.top + axes.height + 26, f"({verdict})", 9)
    return canvas.render()


def _diverging(value: float) -> str:
    """-1 blue .. 0 white .. +1 red."""
    v = max(-1.0, min(1.0, value)) if math.isfinite(value) else 0.0
    fade = round(255 * (1 - abs(v)))
    return f"rgb(255,{fade},{fade})" if v > 0 else f"rgb({fade},{fade},255)"


def correlation_matrix(diagnosis: Diagnosis) -> str:
    """Correlations of the free parameters (-1 blue, 0 white, +1 red)."""
    fit = diagnosis.fit
    free = np.flatnonzero(~fit.fixed)
    std = fit.std[free]
    cov = fit.covariance[np.ix_(free, free)]
    rho = cov / np.maximum(np.outer(std, std), 1e-300)
    labels = [fit.names[k] for k in free]
    size = free.size
    cell = max(6.0, min(22.0, 420.0 / max(size, 1)))
    margin = 6.0 * max((len(s) for s in labels), default=4) + 10
    side = cell * size
    canvas = Canvas(margin + side + 20, margin + side + 40,
                    "correlation matrix of the free parameters")
    axes = canvas.axes(margin, 30, side, side, (0.0, float(size)), (0.0, float(size)))
    i, j = np.meshgrid(np.arange(size), np.arange(size), indexing="ij")
    axes.rects(j.ravel().astype(float), j.ravel() + 1.0, (size - 1 - i.ravel()).astype(float),
               (size - i.ravel()).astype(float), [_diverging(v) for v in rho.ravel()])
    axes.frame("parameter correlations (blue -1, white 0, red +1)", xticks=False,
               yticks=False)
    font = min(9.0, cell * 0.8)
    axes.category_labels(labels, [size - k - 0.5 for k in range(size)], font)
    for k, label in enumerate(labels):
        x = axes.left + (k + 0.5) * cell + font / 3
        y = axes.top + side + 4
        canvas.extra.append(f'<text x="{x:.1f}" y="{y:.1f}" font-size="{font:g}" '
                            f'text-anchor="end" transform="rotate(-90 {x:.1f} {y:.1f})">'
                            f"{html.escape(label)}</text>")
    return canvas.render()


def singular_values(diagnosis: Diagnosis) -> str:
    """Relative singular values of the normalised Jacobian (identifiability)."""
    values = np.maximum(np.asarray(diagnosis.fit.singular_values, dtype=float), 1e-18)
    canvas = Canvas(520, 300, "relative singular values of the Jacobian")
    index = np.arange(1, values.size + 1, dtype=float)
    low = min(float(values.min(initial=1.0)), RELATIVE_RANK_TOLERANCE) / 3
    high = max(float(values.max(initial=1.0)), 1.0) * 3
    axes = canvas.axes(60, 28, 430, 220, (0.5, values.size + 0.5), (low, high), log_y=True)
    axes.line(index, values, COLOURS[0], 1.2, markers=5.0)
    axes.hline(RELATIVE_RANK_TOLERANCE, SIGNIFICANT, 1.0, "4 3")
    axes.frame(f"identifiability: rank {diagnosis.fit.rank} of {values.size}", "index",
               "relative singular value")
    axes.legend([("singular values", COLOURS[0]), ("rank tolerance", SIGNIFICANT)],
                corner="bottom left")
    return canvas.render()
