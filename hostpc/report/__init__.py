"""Reports: one self-contained HTML file of a diagnosis (plots embedded as base64 PNG).

    from hostpc.report import write_report
    write_report("run/report.html", hostpc.diagnose(dataset, ladder=True))
"""

from hostpc.report.html import render_html, write_report

__all__ = ["write_report", "render_html"]
