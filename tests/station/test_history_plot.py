"""The history plot a person reads: each joint's zero against the calibrations' dates
(not "calibration #"), with the drift threshold drawn as the band around the previous
calibration's zero that the next one may reach without an alarm."""

from __future__ import annotations

from datetime import UTC, datetime, timedelta

import matplotlib.dates as mdates
import pytest
from matplotlib.collections import PolyCollection

from hostpc.archive.drift import drift_findings
from hostpc.archive.history_page import drift_figure, drift_plot_png
from hostpc.archive.records import JointOffset
from hostpc.archive.rows import ArchivedRun


def _runs() -> list[ArchivedRun]:
    start = datetime(2026, 3, 2, 9, 0, tzinfo=UTC)
    zeros = [0.100, 0.105, 0.140]  # the last step (35 mdeg) beyond the 20 mdeg threshold
    stamps = [(start + timedelta(days=7 * k)).isoformat() for k in range(len(zeros))]
    return [ArchivedRun(
        id=k + 1, run_uid=f"uid-{k}", serial="SN-9", model="ur5e", station="cell",
        started_at=stamp, archived_at=stamp, method="stereo_target", effects=(),
        verdict="PASS", exit_code=0, push_status="pushed", largest_correction_deg=None,
        software_version="test", run_dir="", revision=1, reason=None, report_path=None,
        offsets=(JointOffset(joint=2, label="q2", old_deg=None, correction_deg=None,
                             sigma_deg=0.001, new_deg=zero, pushed=True),))
        for k, (zero, stamp) in enumerate(zip(zeros, stamps, strict=True))]


def test_the_plot_is_against_dates_with_the_threshold_drawn() -> None:
    import matplotlib.pyplot as plt

    runs = _runs()
    findings = drift_findings(runs, threshold_deg=0.02)
    assert [f.to_run for f in findings] == [3]
    figure = drift_figure(runs, findings, threshold_deg=0.02)
    try:
        axis = figure.axes[0]
        assert "date" in axis.get_xlabel() and "calibration #" not in axis.get_xlabel()
        assert isinstance(axis.xaxis.get_major_formatter(), mdates.ConciseDateFormatter)
        left, right = axis.get_xlim()  # matplotlib date numbers: the runs' dates
        first = mdates.date2num(datetime(2026, 3, 2, 9, 0, tzinfo=UTC))
        assert left <= first and right >= first + 14
        bands = [c for c in axis.collections if c.get_label() == "drift threshold"]
        assert len(bands) == 1
        # the bands: +-20 mdeg around the previous zero (0 and 5 mdeg after the first)
        fills = [c for c in axis.collections if isinstance(c, PolyCollection)]
        lows_highs = [(round(float(path.vertices[:, 1].min()), 6),
                       round(float(path.vertices[:, 1].max()), 6))
                      for fill in fills for path in fill.get_paths()]
        assert lows_highs == [(-20.0, 20.0), (-15.0, 25.0)]
    finally:
        plt.close(figure)
    assert drift_plot_png(runs, findings).startswith(b"\x89PNG")


@pytest.mark.parametrize("threshold", [0.01, 0.05])
def test_the_band_follows_the_threshold(threshold: float) -> None:
    import matplotlib.pyplot as plt

    figure = drift_figure(_runs(), [], threshold_deg=threshold)
    try:
        band = next(c for c in figure.axes[0].collections
                    if c.get_label() == "drift threshold")
        vertices = band.get_paths()[0].vertices
        assert vertices[:, 1].max() - vertices[:, 1].min() == pytest.approx(
            2000 * threshold)
    finally:
        plt.close(figure)
