"""The outcome in the run folder: derived from the journal, written into every view.

`run_outcome` derives a run's `RobotOutcome` (outcome.py) from its journal; the runner
puts it into result.json at the end of a run or a resume. `rewrite_outcome` does it again
later, when the journal changed after the result was written (`hostpc rollback --run`):
result.json's "outcome" block and exit code, summary.txt and report.html are rewritten so
no view keeps saying PASS for offsets that were rolled back. The previous result.json and
summary.txt are kept as result.N.json / summary.N.txt (resume.archive_result).
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Sequence
from pathlib import Path

from hostpc.calibrate.joint_status import JointSource
from hostpc.calibrate.journal import Journal
from hostpc.calibrate.journal_events import RunFinished
from hostpc.calibrate.outcome import (
    JOURNAL_KINDS,
    RobotOutcome,
    derive_outcome,
    parse_required_joints,
    sources_from_outcome,
)
from hostpc.calibrate.resume import archive_result
from hostpc.calibrate.run_header import RunHeader, read_run_header
from hostpc.calibrate.run_result import RunResult
from hostpc.calibrate.summary import format_summary
from hostpc.errors import InputError
from hostpc.files import write_json_atomic
from hostpc.robots.drivers import DRIVERS


def run_outcome(journal: Journal, sources: Sequence[JointSource], *, run_dir: Path,
                header: RunHeader, require_joints: str | None, finished: bool,
                known: Sequence[str] = (), swapped: Sequence[int] = ()) -> RobotOutcome:
    """The outcome of the run in `run_dir` from its journal and the fit's sources. A joint
    declared swapped (`--swapped`) is required too: the technician said its zero is wrong,
    so a run that cannot calibrate it must not read PASS."""
    required = (*parse_required_joints(require_joints, len(sources)), *swapped)
    driver = DRIVERS.get(header.robot.driver)  # a UR's push stays on the host
    return derive_outcome(journal.timeline(*JOURNAL_KINDS), sources, run_dir=str(run_dir),
                          finished=finished, required=required,
                          new_run=header.new_run_options(), known=known, swapped=swapped,
                          host_offsets=driver.host_offsets if driver is not None else None,
                          archive=header.archive, simulated=header.robot.sim)


def rewrite_outcome(run_dir: Path) -> RobotOutcome | None:
    """Derive the outcome of a finished run again from its journal and rewrite result.json,
    summary.txt and report.html (if the run has one) with it. None (nothing written) if
    the run has no result.json or one without an outcome block (an older version's)."""
    path = run_dir / "result.json"
    try:
        document = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        return None
    except (OSError, ValueError) as exc:
        raise InputError(f"{path}: cannot read ({exc})") from None
    if not isinstance(document.get("outcome"), dict):
        return None
    stored = RunResult.from_dict(document)
    journal = Journal(run_dir)
    header = read_run_header(journal)
    journal.load()
    outcome = run_outcome(journal, sources_from_outcome(document["outcome"]), run_dir=run_dir,
                          header=header, require_joints=header.settings.require_joints,
                          swapped=header.settings.swapped,  # run.json: every declaration
                          finished=journal.last(RunFinished) is not None,
                          known=stored.known)
    run = dataclasses.replace(stored, outcome=outcome.to_dict(), exit_code=outcome.exit_code)
    if outcome.verdict == "ROLLED_BACK":
        run = dataclasses.replace(
            run, push=dataclasses.replace(run.push, status="rolled_back"),
            offsets=tuple(dataclasses.replace(row, pushed=False) for row in run.offsets))
    summary = format_summary(run)
    archive_result(run_dir)
    (run_dir / "summary.txt").write_text(summary + "\n", encoding="utf-8")
    write_json_atomic(path, run.to_dict())
    if (run_dir / "report.html").is_file():
        _render_report(run_dir, run)
    return outcome


def _render_report(run_dir: Path, run: RunResult) -> None:
    """report.html again with the new outcome (the diagnosis of the run's dataset too)."""
    from hostpc.report import write_calibration_report

    diagnosis = None
    dataset = run_dir / "dataset.json"
    if dataset.is_file():
        from hostpc.diagnostics import diagnose

        settings = run.settings
        effects = run.fit.get("effects") or settings.get("effects")
        diagnosis = diagnose(dataset, effects, plugins=settings.get("plugins") or [],
                             loss=settings.get("loss") or "linear", source=str(dataset))
    truth_file = run_dir / "sim" / "truth.json"
    truth = json.loads(truth_file.read_text()) if truth_file.is_file() else None
    write_calibration_report(run_dir / "report.html", run.to_dict(), diagnosis, truth)
