"""A small SVG plotter for the report: axes with ticks, points, lines, bars, a heat map.

Why not matplotlib: a report of eight figures took 3-4 s to rasterise with it (text layout
and PNG encoding), most of a simulated calibration's wall time; these figures are the same
data drawn as inline SVG text in milliseconds, sharp at any zoom, and need no image
decoding in the browser. Pure string building on numpy arrays: no I/O, no global state.

Coordinates: a ``Canvas`` is ``width`` x ``height`` pixels; ``Canvas.axes`` places a plot
area (left, top, width, height in pixels) with data limits; data are drawn inside a nested
``<svg>`` viewport, which clips what falls outside the limits.
"""

from __future__ import annotations

import html
import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

FONT = 'font-family="system-ui, sans-serif"'
GRID = "#e6e6e6"
INK = "#222"
#: smallest font (px) of level names on an x axis; the width of one character and the gap
#: between two names, in font sizes (a sans-serif digit is ~0.55 em)
MIN_LABEL_FONT = 7.0
LABEL_CHAR_EM = 0.6
LABEL_GAP_EM = 0.8


def _e(text: object) -> str:
    return html.escape(str(text), quote=True)


def _f(value: float) -> str:
    """A pixel coordinate, short: one decimal."""
    return f"{value:.1f}"


def nice_ticks(low: float, high: float, count: int = 5) -> list[float]:
    """About ``count`` round tick values (1, 2, 5 x 10^k steps) covering [low, high]."""
    if not (math.isfinite(low) and math.isfinite(high)) or high <= low:
        return [low] if math.isfinite(low) else []
    raw = (high - low) / max(count, 1)
    magnitude = 10.0 ** math.floor(math.log10(raw))
    step = next(s * magnitude for s in (1.0, 2.0, 5.0, 10.0) if s * magnitude >= raw)
    first = math.ceil(low / step - 1e-9) * step
    ticks = []
    value = first
    while value <= high + 1e-9 * step:
        ticks.append(0.0 if abs(value) < 1e-12 * step else value)
        value += step
    return ticks


def tick_label(value: float, step: float) -> str:
    """A tick value with as many decimals as its step needs (scientific when tiny/huge)."""
    if value == 0.0:
        return "0"
    if abs(value) >= 1e5 or abs(value) < 1e-3:
        return f"{value:.0e}"
    decimals = max(0, -math.floor(math.log10(step) + 1e-9)) if step > 0 else 0
    return f"{value:.{decimals}f}"


def limits(values: Sequence[float] | np.ndarray, pad: float = 0.05,
           include: Sequence[float] = ()) -> tuple[float, float]:
    """Data limits of the finite values (and ``include``), padded by a fraction."""
    data = np.asarray(values, dtype=float).ravel()
    data = np.concatenate([data[np.isfinite(data)], np.asarray(include, dtype=float)])
    if data.size == 0:
        return (0.0, 1.0)
    low, high = float(data.min()), float(data.max())
    if high - low <= 1e-300:
        span = abs(low) * 0.1 or 1.0
        return (low - span, high + span)
    margin = (high - low) * pad
    return (low - margin, high + margin)


@dataclass
class Axes:
    """One plot area: pixel box (left, top, width, height) and data limits; ``log_y``
    draws y on a log10 scale (limits are then in data units, positive)."""

    left: float
    top: float
    width: float
    height: float
    xlim: tuple[float, float]
    ylim: tuple[float, float]
    log_y: bool = False
    inner: list[str] = field(default_factory=list)   # inside the clipping viewport
    outer: list[str] = field(default_factory=list)   # frame, ticks, labels

    def _ty(self, y: np.ndarray) -> np.ndarray:
        return np.log10(np.maximum(y, 1e-300)) if self.log_y else y

    def px(self, x: Sequence[float] | np.ndarray) -> np.ndarray:
        """x data -> pixels inside the viewport."""
        lo, hi = self.xlim
        return (np.asarray(x, dtype=float) - lo) / (hi - lo) * self.width

    def py(self, y: Sequence[float] | np.ndarray) -> np.ndarray:
        """y data -> pixels inside the viewport (up is up)."""
        lo, hi = self._ty(np.asarray(self.ylim, dtype=float))
        fraction = (self._ty(np.asarray(y, dtype=float)) - lo) / (hi - lo)
        return np.asarray(self.height - fraction * self.height, dtype=float)

    # ---------------------------------------------------------------- marks

    def points(self, x: Sequence[float] | np.ndarray, y: Sequence[float] | np.ndarray,
               colour: str, size: float = 3.0, opacity: float = 1.0) -> None:
        """Round dots of diameter ``size`` px: one path of zero-length segments."""
        xs, ys = self.px(x), self.py(y)
        keep = np.isfinite(xs) & np.isfinite(ys)
        if not np.any(keep):
            return
        path = "".join(f"M{a:.1f} {b:.1f}h0" for a, b in zip(xs[keep], ys[keep], strict=True))
        self.inner.append(f'<path d="{path}" stroke="{colour}" stroke-width="{size:g}" '
                          f'stroke-linecap="round" stroke-opacity="{opacity:g}"/>')

    def line(self, x: Sequence[float] | np.ndarray, y: Sequence[float] | np.ndarray,
             colour: str, width: float = 1.2, dash: str | None = None,
             markers: float = 0.0) -> None:
        """A polyline through the finite points (a gap at NaN), optional dot markers."""
        xs, ys = self.px(x), self.py(y)
        segments, current = [], []
        for a, b in zip(xs, ys, strict=True):
            if math.isfinite(a) and math.isfinite(b):
                current.append(f"{a:.1f} {b:.1f}")
            elif current:
                segments.append(current)
                current = []
        if current:
            segments.append(current)
        path = "".join("M" + "L".join(s) for s in segments)
        if path:
            dashes = f' stroke-dasharray="{dash}"' if dash else ""
            self.inner.append(f'<path d="{path}" fill="none" stroke="{colour}" '
                              f'stroke-width="{width:g}"{dashes}/>')
        if markers:
            self.points(x, y, colour, markers)

    def hline(self, y: float, colour: str = INK, width: float = 0.8,
              dash: str | None = None) -> None:
        if math.isfinite(y):
            self.line(self.xlim, [y, y], colour, width, dash)

    def vline(self, x: float, colour: str = INK, width: float = 0.8,
              dash: str | None = None) -> None:
        if math.isfinite(x):
            lo, hi = self.ylim
            self.line([x, x], [lo, hi], colour, width, dash)

    def rects(self, x0: np.ndarray, x1: np.ndarray, y0: np.ndarray, y1: np.ndarray,
              colours: Sequence[str]) -> None:
        """Filled rectangles between data corners (bars, histogram, heat map cells)."""
        ax0, ax1, ay0, ay1 = self.px(x0), self.px(x1), self.py(y0), self.py(y1)
        for a0, a1, b0, b1, colour in zip(ax0, ax1, ay0, ay1, colours, strict=True):
            if not all(math.isfinite(v) for v in (a0, a1, b0, b1)):
                continue
            self.inner.append(f'<rect x="{_f(min(a0, a1))}" y="{_f(min(b0, b1))}" '
                              f'width="{_f(abs(a1 - a0))}" height="{_f(abs(b1 - b0))}" '
                              f'fill="{colour}"/>')

    # ---------------------------------------------------------------- frame

    def frame(self, title: str = "", xlabel: str = "", ylabel: str = "",
              title_colour: str = INK, xticks: bool = True, yticks: bool = True,
              font: float = 11.0) -> None:
        """Border, grid, ticks and their labels, axis labels and the title."""
        L, T, W, H = self.left, self.top, self.width, self.height
        small = font - 1.5
        grid: list[str] = []  # drawn behind the marks
        if xticks:
            values = nice_ticks(*self.xlim)
            step = values[1] - values[0] if len(values) > 1 else 1.0
            for v, p in zip(values, self.px(values), strict=True):
                grid.append(f'<path d="M{p:.1f} 0V{H:.1f}" stroke="{GRID}"/>')
                self.outer.append(f'<text x="{_f(L + p)}" y="{_f(T + H + small + 3)}" '
                                  f'font-size="{small:g}" text-anchor="middle">'
                                  f"{_e(tick_label(v, step))}</text>")
        if yticks:
            if self.log_y:
                lo, hi = np.log10(np.asarray(self.ylim, dtype=float))
                values = [10.0**k for k in range(math.ceil(lo), math.floor(hi) + 1)]
                values = values[:: max(1, len(values) // 6)]
                labels = [f"1e{round(math.log10(v))}" for v in values]
            else:
                values = nice_ticks(*self.ylim)
                step = values[1] - values[0] if len(values) > 1 else 1.0
                labels = [tick_label(v, step) for v in values]
            for label, p in zip(labels, self.py(values), strict=True):
                grid.append(f'<path d="M0 {p:.1f}H{W:.1f}" stroke="{GRID}"/>')
                self.outer.append(f'<text x="{_f(L - 3)}" y="{_f(T + p + small / 3)}" '
                                  f'font-size="{small:g}" text-anchor="end">{_e(label)}</text>')
        self.inner[:0] = grid
        if title:
            self.outer.append(f'<text x="{_f(L + W / 2)}" y="{_f(T - 6)}" font-size="{font:g}" '
                              f'text-anchor="middle" fill="{title_colour}">{_e(title)}</text>')
        if xlabel:
            self.outer.append(f'<text x="{_f(L + W / 2)}" y="{_f(T + H + 2 * small + 8)}" '
                              f'font-size="{small:g}" text-anchor="middle">{_e(xlabel)}</text>')
        if ylabel:
            x, y = L - 40, T + H / 2
            self.outer.append(f'<text x="{_f(x)}" y="{_f(y)}" font-size="{small:g}" '
                              f'text-anchor="middle" transform="rotate(-90 {_f(x)} {_f(y)})">'
                              f"{_e(ylabel)}</text>")

    def category_labels(self, labels: Sequence[str], positions: Sequence[float] | np.ndarray,
                        font: float = 9.0) -> None:
        """Labels left of the plot area at the y data positions (horizontal bars)."""
        for label, p in zip(labels, self.py(positions), strict=True):
            self.outer.append(f'<text x="{_f(self.left - 4)}" y="{_f(self.top + p + font / 3)}" '
                              f'font-size="{font:g}" text-anchor="end">{_e(label)}</text>')

    def level_labels(self, labels: Sequence[str], positions: Sequence[float] | np.ndarray,
                     font: float = 8.5, min_font: float = MIN_LABEL_FONT) -> None:
        """Labels below the plot area at the x data positions (in order), with a grid line
        at every position: the level names of a group label (the x ticks of a categorical
        variable). The font shrinks from ``font`` to fit the spacing, but not below
        ``min_font``; where even that does not fit, every k-th level is named (the first
        always), so no two names overlap."""
        x = self.px(positions)
        for p in x:
            self.inner.insert(0, f'<path d="M{p:.1f} 0V{self.height:.1f}" stroke="{GRID}"/>')
        if not len(labels):
            return
        spacing = max(float(np.min(np.diff(np.sort(x)))), 1e-9) if x.size > 1 else math.inf
        em = LABEL_CHAR_EM * max(len(str(label)) for label in labels) + LABEL_GAP_EM
        size = max(min_font, min(font, spacing / em))
        every = max(1, math.ceil(size * em / spacing)) if math.isfinite(spacing) else 1
        for label, p in list(zip(labels, x, strict=True))[::every]:
            self.outer.append(f'<text x="{_f(self.left + p)}" '
                              f'y="{_f(self.top + self.height + size + 2)}" '
                              f'font-size="{size:.3g}" text-anchor="middle">{_e(label)}</text>')

    def legend(self, entries: Sequence[tuple[str, str]], font: float = 9.0,
               corner: str = "right") -> None:
        """(label, colour) entries in a box in a corner of the plot area: "right", "left"
        (top) or "bottom right", "bottom left"."""
        if not entries:
            return
        width = 22 + 0.56 * font * max(len(label) for label, _ in entries)
        height = len(entries) * (font + 4) + 4
        x = self.left + self.width - width - 4 if corner.endswith("right") else self.left + 4
        y = (self.top + self.height - height - 4 if corner.startswith("bottom")
             else self.top + 4)
        parts = [f'<rect x="{_f(x)}" y="{_f(y)}" width="{_f(width)}" height="{_f(height)}" '
                 f'fill="white" fill-opacity="0.85" stroke="#ccc"/>']
        for k, (label, colour) in enumerate(entries):
            cy = y + 4 + (k + 0.5) * (font + 4)
            parts.append(f'<path d="M{_f(x + 4)} {_f(cy)}h12" stroke="{colour}" '
                         f'stroke-width="2.5"/>')
            parts.append(f'<text x="{_f(x + 20)}" y="{_f(cy + font / 3)}" '
                         f'font-size="{font:g}">{_e(label)}</text>')
        self.outer.extend(parts)

    def render(self) -> str:
        box = (f'x="{_f(self.left)}" y="{_f(self.top)}" width="{_f(self.width)}" '
               f'height="{_f(self.height)}"')
        return (f"<svg {box}>{''.join(self.inner)}</svg>"
                f'<rect {box} fill="none" stroke="#888"/>{"".join(self.outer)}')


@dataclass
class Canvas:
    """One figure: ``width`` x ``height`` px, a title for screen readers, its axes."""

    width: float
    height: float
    label: str
    panels: list[Axes] = field(default_factory=list)
    extra: list[str] = field(default_factory=list)

    def axes(self, left: float, top: float, width: float, height: float,
             xlim: tuple[float, float], ylim: tuple[float, float], log_y: bool = False) -> Axes:
        panel = Axes(left, top, width, height, xlim, ylim, log_y)
        self.panels.append(panel)
        return panel

    def text(self, x: float, y: float, text: str, size: float = 11.0,
             anchor: str = "middle") -> None:
        self.extra.append(f'<text x="{_f(x)}" y="{_f(y)}" font-size="{size:g}" '
                          f'text-anchor="{anchor}">{_e(text)}</text>')

    def render(self) -> str:
        """The figure as one ``<svg>`` element (scales down with the page width)."""
        body = "".join(p.render() for p in self.panels) + "".join(self.extra)
        return (f'<svg xmlns="http://www.w3.org/2000/svg" class="plot" role="img" '
                f'aria-label="{_e(self.label)}" viewBox="0 0 {self.width:g} {self.height:g}" '
                f'width="{self.width:g}" height="{self.height:g}" {FONT} fill="{INK}">'
                f"<title>{_e(self.label)}</title>{body}</svg>")
