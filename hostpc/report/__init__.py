"""Reports: one self-contained HTML file (figures inline SVG, no scripts, no external files).

A diagnosis alone (``hostpc diagnose --report``):

    from hostpc.report import write_report
    write_report("run/report.html", hostpc.diagnose(dataset, ladder=True))

A calibration run (``hostpc calibrate`` writes RUN/report.html): its result first (verdict,
offsets, verification, truth for a simulated run), then the diagnosis:

    from hostpc.report import write_calibration_report
    write_calibration_report("run/report.html", result_document, diagnosis, truth)
"""

from hostpc.report.calibration import render_calibration_html, write_calibration_report
from hostpc.report.html import render_html, write_report

__all__ = ["write_report", "render_html", "write_calibration_report",
           "render_calibration_html"]
