"""A calibration run's report.html: the result (verdict, offsets, verification, truth), then
the diagnosis of its dataset. An extra: a failure to write it never loses a run."""

from __future__ import annotations

from pathlib import Path

from hostpc.calibrate.run_result import RunResult
from hostpc.dataset import Dataset
from hostpc.diagnostics import diagnose
from hostpc.json_object import JsonObject
from hostpc.methods.base import Progress, RunSettings
from hostpc.report import write_calibration_report


def write_run_report(run_dir: Path, dataset: Dataset, settings: RunSettings,
                     run: RunResult, truth: JsonObject | None,
                     progress: Progress) -> str | None:
    """Write RUN/report.html; returns its path, or None (the reason as a progress message)."""
    progress.stage("report")
    path = run_dir / "report.html"
    try:
        diagnosis = diagnose(dataset, settings.effects, plugins=settings.plugins,
                             source=str(run_dir / "dataset.json"))
        # the report (a pure layer) reads the result in its JSON form
        write_calibration_report(path, run.to_dict(), diagnosis, truth)
    except Exception as exc:  # the report is an extra: never lose a run over it
        progress.message(f"report not written: {type(exc).__name__}: {exc}")
        return None
    return str(path)
