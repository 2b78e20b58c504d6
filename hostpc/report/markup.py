"""HTML building blocks shared by the report pages: escaping, number formats, tables, the
page shell and its style sheet. Numbers arrive in SI units; ``mm`` and ``display`` turn
them into the mm and degrees a reader sees (docs/conventions.md)."""

from __future__ import annotations

import html
import math
from collections.abc import Iterable, Sequence

from hostpc.display_units import DISPLAY_UNITS

#: the display units of the CLI, and latencies in ms
DISPLAY = {**DISPLAY_UNITS, "s": ("ms", 1e3)}

STYLE = """
body { font-family: system-ui, sans-serif; margin: 2em auto; max-width: 1200px;
       color: #222; line-height: 1.4; padding: 0 1em; }
h1 { font-size: 1.6em; } h2 { border-bottom: 1px solid #ccc; padding-bottom: 0.2em; }
table { border-collapse: collapse; margin: 0.5em 0 1em; font-size: 0.9em; }
th, td { border: 1px solid #ddd; padding: 0.25em 0.6em; text-align: right; }
th { background: #f4f4f4; } td.name, th.name { text-align: left; font-family: monospace; }
td.text, th.text { text-align: left; }
.verdict { padding: 0.8em 1em; border-radius: 6px; font-size: 1.1em; font-weight: bold; }
.verdict p { margin: 0.3em 0 0; font-size: 0.85em; font-weight: normal; }
.good { background: #e5f5e0; border: 1px solid #74c476; }
.bad { background: #fee0d2; border: 1px solid #fb6a4a; }
.neutral { background: #fff7dc; border: 1px solid #e6b940; }
.significant { color: #c00; font-weight: bold; }
svg.plot { max-width: 100%; height: auto; display: block; margin: 0.5em 0; }
.row { display: flex; flex-wrap: wrap; gap: 1em; align-items: flex-start; }
code { background: #f4f4f4; padding: 0 0.2em; }
.note { color: #555; font-size: 0.9em; }
"""


def escape(value: object) -> str:
    return html.escape(str(value))


def prose(value: object) -> str:
    """A sentence as HTML: escaped, and each command the text quotes between backticks
    (`hostpc diagnose RUN/dataset.json`) set as code, never shown with its backticks."""
    parts = escape(value).split("`")
    if len(parts) % 2 == 0:  # an unpaired backtick: no command to mark, drop none
        return escape(value)
    return "".join(f"<code>{part}</code>" if k % 2 else part for k, part in enumerate(parts))


def mm(value: float | None) -> str:
    """Metres as mm with 4 decimals; '-' for None and non-finite."""
    return "-" if value is None or not math.isfinite(value) else f"{value * 1e3:.4f}"


def num(value: float | None, digits: int = 3) -> str:
    return "-" if value is None or not math.isfinite(value) else f"{value:.{digits}f}"


def p_value(value: float | None) -> str:
    return "-" if value is None or not math.isfinite(value) else f"{value:.2g}"


def display(value: float | None, unit: str, signed: bool = True) -> tuple[str, str]:
    """(value in the unit a reader sees, that unit): rad -> deg, m -> mm, ..."""
    shown, factor = DISPLAY.get(unit, (unit, 1.0))
    if value is None or not math.isfinite(value):
        return "-", shown
    text = f"{value * factor:+.5g}" if signed else f"{value * factor:.5g}"
    return text, shown


def table(header: Sequence[str], rows: Iterable[Sequence[str]], name_columns: int = 1,
          flags: Iterable[bool] | None = None, table_id: str | None = None,
          text_columns: Sequence[int] = ()) -> str:
    """An HTML table; cells are already escaped; the first name_columns are left-aligned
    names, ``text_columns`` left-aligned prose; rows whose flag is True are marked (class
    "significant")."""

    def cls(k: int) -> str:
        if k < name_columns:
            return ' class="name"'
        return ' class="text"' if k in text_columns else ""

    head = "".join(f"<th{cls(k)}>{h}</th>" for k, h in enumerate(header))
    body = []
    flag_list = list(flags) if flags is not None else None
    for r, row in enumerate(rows):
        mark = ' class="significant"' if flag_list and flag_list[r] else ""
        cells = "".join(f"<td{cls(k)}>{c}</td>" for k, c in enumerate(row))
        body.append(f"<tr{mark}>{cells}</tr>")
    ident = f' id="{escape(table_id)}"' if table_id else ""
    return (f"<table{ident}><thead><tr>{head}</tr></thead><tbody>{''.join(body)}</tbody>"
            "</table>")


def figure(svg: str) -> str:
    """An inline SVG figure (from hostpc.report.plots)."""
    return f'<figure style="margin:0">{svg}</figure>'


def page(title: str, body: str) -> str:
    """The complete, self-contained HTML document."""
    return (f'<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
            f'<meta name="viewport" content="width=device-width, initial-scale=1">'
            f"<title>{escape(title)}</title><style>{STYLE}</style></head>\n"
            f"<body>\n{body}\n</body></html>\n")
