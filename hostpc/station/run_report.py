"""The report.html of a station run for which `hostpc calibrate` wrote none (it was
refused its input, could not start, or was aborted before its result): every station run
has a report, archived with it. It says what the station knows: the robot, the verdict,
the result code, the one-line reason and the end of the run's log."""

from __future__ import annotations

import html
from pathlib import Path

LOG_TAIL_LINES = 40


def write_station_report(path: Path, *, serial: str, model: str, station: str,
                         started_at: str, verdict: str, result_code: int, reason: str,
                         log_path: Path | None) -> None:
    """Write `path` (its folder created); OSError if it cannot be written."""
    tail = ""
    if log_path is not None and log_path.is_file():
        lines = log_path.read_text(errors="replace").splitlines()[-LOG_TAIL_LINES:]
        tail = "\n".join(lines)
    rows = [("robot", serial), ("model", model), ("station", station),
            ("started", started_at), ("verdict", verdict), ("result code", str(result_code)),
            ("reason", reason or "-")]
    table = "".join(f"<tr><th>{html.escape(k)}</th><td id='{k.replace(' ', '-')}'>"
                    f"{html.escape(v)}</td></tr>" for k, v in rows)
    title = f"zerocal station run of {serial}: {verdict}"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(
        f"<!doctype html><html><head><meta charset='utf-8'><title>{html.escape(title)}"
        "</title><style>body{font-family:sans-serif;margin:2em;max-width:60em}"
        "td,th{border:1px solid #bbb;padding:3px 8px;text-align:left}"
        "table{border-collapse:collapse}pre{background:#f4f4f4;padding:1em;overflow:auto}"
        f"</style></head><body><h1>{html.escape(title)}</h1>"
        "<p>The calibration wrote no report of its own: what the station knows of the run."
        f"</p><table>{table}</table><h2>End of the run's log</h2>"
        f"<pre>{html.escape(tail) or '(no output)'}</pre></body></html>\n")
