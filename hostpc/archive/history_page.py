"""The archive's history as a self-contained HTML page: the fleet (last verdict per robot,
robots whose zeros move most), drift findings, and per robot its zeros over time with
their sigmas (a plot per robot, drift marked in red)."""

from __future__ import annotations

import base64
import html
import io
from collections.abc import Sequence
from datetime import datetime
from pathlib import Path
from typing import TYPE_CHECKING

from hostpc.archive.drift import (
    DEFAULT_THRESHOLD_DEG,
    DriftFinding,
    by_robot,
    fleet_summary,
    zero_series,
)
from hostpc.archive.rows import ArchivedRun

if TYPE_CHECKING:
    from matplotlib.figure import Figure


def local_time(stamp: str) -> str:
    """An archive timestamp (ISO 8601, UTC) as the operator reads it: to the second, in this
    computer's local time zone, named ("2026-03-02 14:05:09 CET")."""
    return datetime.fromisoformat(stamp).astimezone().strftime("%Y-%m-%d %H:%M:%S %Z")


def drift_plot_png(runs: Sequence[ArchivedRun], findings: list[DriftFinding],
                   threshold_deg: float = DEFAULT_THRESHOLD_DEG) -> bytes:
    """`drift_figure` as a PNG."""
    figure = drift_figure(runs, findings, threshold_deg)  # selects the Agg backend first
    import matplotlib.pyplot as plt

    buffer = io.BytesIO()
    figure.savefig(buffer, format="png", dpi=80)
    plt.close(figure)
    return buffer.getvalue()


def drift_figure(runs: Sequence[ArchivedRun], findings: list[DriftFinding],
                 threshold_deg: float = DEFAULT_THRESHOLD_DEG) -> Figure:
    """One robot's zero of each joint against the calibrations' dates (local time; deg,
    change from the first calibration, error bars = 1 sigma); joints with a drift finding
    are drawn in red. The drift threshold is drawn as the band a calibration's zero may
    lie in without an alarm: +-`threshold_deg` around the previous calibration's zero."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.dates as mdates
    import matplotlib.pyplot as plt

    series = zero_series(runs)
    drifting = {f.label for f in findings}
    labels = sorted(series, key=lambda s: (len(s), s))
    figure, axes = plt.subplots(max(1, len(labels)), 1, figsize=(7, 1.5 + 1.25 * len(labels)),
                                sharex=True, squeeze=False)
    zone = datetime.now().astimezone().tzinfo
    threshold_mdeg = threshold_deg * 1000.0
    for axis, label in zip(axes[:, 0], labels, strict=False):
        points = series[label]
        x = [datetime.fromisoformat(p[1]).astimezone(zone) for p in points]
        base = points[0][2]
        y = [(p[2] - base) * 1000.0 for p in points]
        err = [0.0 if p[3] is None else p[3] * 1000.0 for p in points]
        for k in range(1, len(points)):  # the band the next zero may lie in
            axis.fill_between([x[k - 1], x[k]], y[k - 1] - threshold_mdeg,
                              y[k - 1] + threshold_mdeg, color="tab:orange", alpha=0.15,
                              lw=0, label="drift threshold" if k == 1 else None)
            axis.plot([x[k], x[k]], [y[k - 1] - threshold_mdeg, y[k - 1] + threshold_mdeg],
                      color="tab:orange", lw=1.0, ls="--")
        colour = "tab:red" if label in drifting else "tab:blue"
        axis.errorbar(x, y, yerr=err, marker="o", color=colour, capsize=3, lw=1.2)
        axis.set_ylabel(f"{label}\n[mdeg]", fontsize=8)
        axis.grid(alpha=0.3)
        axis.tick_params(labelsize=8)
    locator = mdates.AutoDateLocator(tz=zone)  # type: ignore[no-untyped-call]
    axes[-1, 0].xaxis.set_major_locator(locator)
    formatter = mdates.ConciseDateFormatter(locator, tz=zone)  # type: ignore[no-untyped-call]
    axes[-1, 0].xaxis.set_major_formatter(formatter)
    axes[-1, 0].set_xlabel(f"date of the calibration ({datetime.now().astimezone():%Z})",
                           fontsize=9)
    if runs:
        figure.suptitle(f"zero offsets of {runs[0].serial} (change since first "
                        f"calibration; band: +-{threshold_deg:g} deg drift threshold from the "
                        "previous one)", fontsize=9)
    figure.tight_layout()
    return figure


def _cell(value: object, verdict: bool = False) -> str:
    """A table cell: a float to 4 decimals, anything else as text; a verdict is styled."""
    text = f"{value:.4f}" if isinstance(value, float) else str(value)
    css = f' class="{html.escape(text)}"' if verdict else ""
    return f"<td{css}>{html.escape(text)}</td>"


def _report_cell(path: str | None) -> str:
    """A cell linking a run's report.html (file URL), or an empty one."""
    link = (f"<a class='report' href='{html.escape(report_url(path))}'>report</a>"
            if path else "")
    return f"<td>{link}</td>"


def _table(titles: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    """An HTML table of `titles` over rows of rendered cells (`_cell`, `_report_cell`)."""
    head = "".join(f"<th>{html.escape(title)}</th>" for title in titles)
    body = ["<tr>" + "".join(cells) + "</tr>" for cells in rows]
    return f"<table><tr>{head}</tr>{''.join(body)}</table>"


STYLE = """body{font-family:sans-serif;margin:2em;max-width:60em}
table{border-collapse:collapse;margin:1em 0}td,th{border:1px solid #bbb;padding:3px 8px;
font-size:90%}th{background:#eee}.PASS{color:#070;font-weight:bold}.FAIL,.ERROR{color:#b00;
font-weight:bold}.alarm{color:#b00}"""


def report_url(path: str) -> str:
    """The URL of a run's report.html as the history page links it (a file URL)."""
    return Path(path).resolve().as_uri()


def history_html(runs: Sequence[ArchivedRun], findings: list[DriftFinding],
                 robot: str | None = None,
                 threshold_deg: float = DEFAULT_THRESHOLD_DEG) -> str:
    """The history page for `runs` (all robots, or the one named `robot`); each run links
    its report.html, each robot's plot draws the drift threshold `threshold_deg`."""
    title = f"zerocal history: {robot}" if robot else "zerocal history: fleet"
    parts = [f"<!doctype html><html><head><meta charset='utf-8'><title>{html.escape(title)}"
             f"</title><style>{STYLE}</style></head><body><h1>{html.escape(title)}</h1>"]
    parts.append("<h2>Fleet: last verdict per robot, largest zero move first</h2>")
    parts.append(_table(
        ["robot", "model", "runs", "last verdict", "last run", "largest zero move [deg]"],
        [[_cell(row.serial), _cell(row.model), _cell(row.runs),
          _cell(row.last_verdict, verdict=True), _cell(local_time(row.last_run)),
          _cell(row.largest_zero_move_deg)] for row in fleet_summary(runs)]))
    parts.append("<h2>Drift alarms</h2>")
    if findings:
        parts.append("<ul>" + "".join(
            f"<li class='alarm'>DRIFT {html.escape(f.serial)} {html.escape(f.label)}: "
            f"{html.escape(f.reason)} (runs {f.from_run} &rarr; {f.to_run})</li>"
            for f in findings) + "</ul>")
    else:
        parts.append("<p>none: no joint zero moved beyond its threshold or uncertainty.</p>")
    parts.append("<h2>Runs</h2>")
    parts.append(_table(
        ["id", "robot", "started", "station", "method", "verdict", "push",
         "largest correction [deg]", "reason", "report"],
        [[_cell(run.id), _cell(run.serial), _cell(local_time(run.started_at)),
          _cell(run.station), _cell(run.method), _cell(run.verdict, verdict=True),
          _cell(run.push_status), _cell(run.largest_correction_deg), _cell(run.reason or ""),
          _report_cell(run.report_path)] for run in runs]))
    for serial, robot_runs in by_robot(runs).items():
        robot_findings = [f for f in findings if f.serial == serial]
        png = base64.b64encode(drift_plot_png(robot_runs, robot_findings,
                                              threshold_deg)).decode()
        parts.append(f"<h2>Robot {html.escape(serial)}</h2><img alt='zero offsets of "
                     f"{html.escape(serial)}' src='data:image/png;base64,{png}'>")
    parts.append("</body></html>")
    return "\n".join(parts)
