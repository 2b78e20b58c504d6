"""The result of a calibration run: the ``result.json`` document and the ``summary.txt`` text.

``run_result`` builds what a run produced (plan, acquisition, fit, offsets, push,
verification, files, outcome) once, as a ``RunResult`` (run_result.py); ``format_summary``
renders it as the human-readable summary (mm and degrees), headline first (the run's outcome,
outcome.py). Exit codes beyond hostpc.errors: 5 = push refused by a guard rail, 6 =
verification of the pushed offsets failed (with nothing pushed the verification is a model
check: reported only), 7 = a joint required by `--require-joints` is not calibrated from
the data (the calibrated joints are still pushed and verified; the verdict is
JOINTS_MISSING, never PASS).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from hostpc.calibrate.journal import Journal
from hostpc.calibrate.journal_events import MorePoses, Pushed
from hostpc.calibrate.next_commands import rollback_command
from hostpc.calibrate.push import PUSH_FILE, PushPlan, joint_display_name
from hostpc.calibrate.robot_time import format_robot_time, robot_time_document
from hostpc.calibrate.run_reference import reference_summary_lines
from hostpc.calibrate.run_result import (
    APPLIED_ON_HOST,
    Acquisition,
    PushResult,
    RunResult,
    SkippedPose,
    plan_as_run,
)
from hostpc.calibrate.run_values import RobotInfo
from hostpc.calibrate.verify import VerifyResult, measured_noise_rms, noise_rms
from hostpc.dataset import Dataset
from hostpc.diagnostics.adequacy import chi2_dof_upper
from hostpc.fitting import FitResult
from hostpc.json_object import JsonObject
from hostpc.methods.base import Method, Plan, RunSettings
from hostpc.methods.cell import Cell

RESULT_FORMAT = "zerocal-calibration/1"
HOST_ONLY_NOTE = "applied on the host for this session only; the controller's zero unchanged"
"""The offset row of a joint whose new offset a robot that keeps none (UR) took on the
host only."""
EXIT_PUSH_REFUSED = 5
EXIT_VERIFY_FAILED = 6
EXIT_JOINTS_NOT_CALIBRATED = 7


def run_result(journal: Journal, run_dir: Path, robot: RobotInfo, settings: RunSettings,
               cell: Cell, plan: Plan, method: Method, dataset: Dataset, result: FitResult,
               push_plan: PushPlan, push_status: str, verify_result: VerifyResult | None,
               truth: JsonObject | None, *, outcome: JsonObject,
               reference_check: JsonObject | None,
               exports: Mapping[str, str] | None) -> RunResult:
    """The result (``result.json``, format ``RESULT_FORMAT``) of a run in `run_dir`, built
    once: settings, plan, acquisition (skipped poses from `journal`), fit, offsets, push
    (with the UR `exports` that are the push, if any), verification, files, the reference
    check, the outcome (``RobotOutcome.to_dict()``) and its exit code; truth (simulation
    only: the simulator's truth document) adds ``truth_comparison``."""
    skipped = tuple(SkippedPose(r.phase, r.index, r.reason)
                    for phase in ("fit", "verify") for r in journal.records(phase)
                    if not r.ok)
    written = push_status == "pushed"
    on_host = exports is not None  # a robot that keeps no offsets: the host's session only
    rows = tuple(dataclasses.replace(row, pushed=row.pushed and written and not on_host,
                                     new_deg=row.new_deg if written else row.old_deg,
                                     note=HOST_ONLY_NOTE if row.pushed and written and on_host
                                     else row.note)
                 for row in push_plan.joints())
    pushes = journal.events(Pushed)
    push = PushResult(push_status, push_plan.refused, push_plan.max_correction_deg,
                      {"rollback_id": pushes[-1].record.rollback_id,
                       "recovered": pushes[-1].recovered,
                       "file": str(run_dir / PUSH_FILE)} if written and pushes else None,
                      exports)
    more = journal.last(MorePoses)
    files = {
        "run": str(journal.run_path),
        "journal": str(journal.journal_path),
        "dataset": str(run_dir / "dataset.json"),
        "fit": str(run_dir / "fit.json"),
        "summary": str(run_dir / "summary.txt"),
        "result": str(run_dir / "result.json"),
        **{f"ur_{kind}": path for kind, path in (exports or {}).items()},
    }
    return RunResult(
        format=RESULT_FORMAT,
        run_dir=str(run_dir),
        robot={**robot.to_dict(), "name": cell.robot},
        method=settings.method,
        settings=settings.to_dict(),
        known=tuple(cell.known),
        method_setup=method.describe(),
        plan={
            "n_poses": int(plan.q.shape[0]),
            "n_verify": int(plan.verify_poses(more is not None).shape[0]),
            **{k: v for k, v in plan_as_run(plan.info, more is not None).items()
               if k != "parameters"},
        },
        acquisition=Acquisition(
            n_planned=int(plan.q.shape[0]) + (int(plan.more.shape[0]) if more else 0),
            more_poses=None if more is None else more.reason,
            n_measured=dataset.n_samples,
            n_poses_measured=sum(r.ok for r in journal.records("fit")),
            skipped=skipped),
        fit={
            "converged": result.converged,
            "effects": list(result.problem.effect_names),
            "rms_mm": result.rms * 1e3,
            "max_mm": result.max * 1e3,
            "chi2_dof": finite_or_none(result.chi2_dof),
            "chi2_dof_upper": finite_or_none(chi2_dof_upper(result.dof)),
            # the chi2/dof the push guard tested instead (shared error inside), if any
            "chi2_dof_with_calibration": (None if push_plan.chi2_dof_tested is None
                                          else finite_or_none(push_plan.chi2_dof_tested)),
            "noise_rms_mm": finite_or_none(measured_noise_rms(result) * 1e3),
            "stated_noise_rms_mm": finite_or_none(noise_rms(dataset) * 1e3),
            "cv_rms_mm": None if result.cv_rms is None else result.cv_rms * 1e3,
            "rank": result.rank,
            "n_parameters": len(result.names),
            "unidentifiable": [d.description for d in result.unidentifiable],
            "file": str(run_dir / "fit.json"),
        },
        offsets=rows,
        push=push,
        verify=verify_result.to_dict() if verify_result is not None else None,
        robot_time_s=robot_time_document(journal),
        files=files,
        exit_code=int(outcome["exit_code"]),  # the verdict every view reads
        truth=None if truth is None else truth_comparison(truth, push_plan),
        reference_check=reference_check,
        outcome=outcome,
    )


def truth_comparison(truth: JsonObject, push_plan: PushPlan) -> JsonObject:
    """Fitted vs injected zero errors (simulation): `joint_offsets_error_deg` = fitted -
    true per joint, None where the joint is unidentifiable; also within 3 sigma."""
    true = np.asarray(truth.get("zero_errors", []), float)
    errors: list[float | None] = []
    within: list[bool | None] = []
    for j in range(true.size):
        if j < push_plan.sigma.size and np.isfinite(push_plan.sigma[j]):
            e = float(push_plan.fitted[j] - true[j])
            errors.append(math.degrees(e))
            within.append(bool(abs(e) <= 3.0 * float(push_plan.sigma[j])))
        else:
            errors.append(None)
            within.append(None)
    finite = [abs(e) for e in errors if e is not None]
    return {
        "zero_errors_deg": [math.degrees(v) for v in true],
        "joint_offsets_error_deg": errors,
        "within_3_sigma": within,
        "max_abs_error_deg": max(finite) if finite else None,
    }


def finite_or_none(value: float) -> float | None:
    """`value`, or None if it is not finite (JSON has no inf/nan)."""
    return value if math.isfinite(value) else None


def format_summary(run: RunResult) -> str:
    """The human-readable summary of a run's result (mm and degrees)."""
    robot, plan, acq, fitd = run.robot, run.plan, run.acquisition, run.fit
    outcome = run.outcome or {}
    lines = [outcome["headline"]] if outcome.get("headline") else []
    n_poses = acq.n_measured if acq.n_poses_measured is None else acq.n_poses_measured
    lines += [
        f"zerocal calibration: {run.method} on {robot['name']} at "
        f"{'sim (' + robot['address'] + ')' if robot.get('sim') else robot['address']}",
        f"run folder: {run.run_dir}",
        f"known frames: {', '.join(run.known) or 'none (every frame estimated)'}",
        plan_line(plan, acq.to_dict()),
        *([f"rig: {run.method_setup['rig']['source']}"]
          if isinstance(run.method_setup.get("rig"), dict)
          and run.method_setup["rig"].get("source") else []),
        (f"measured: {n_poses} of {acq.n_planned} fit poses" if n_poses <= acq.n_planned
         else f"measured: {n_poses} fit poses for a plan of {acq.n_planned} (the plan's "
         "poses measured again, shifted, in coarse-to-fine stages, or further poses)")
        + (f" ({acq.n_measured} samples)" if n_poses != acq.n_measured else "")
        + (f", {len(acq.skipped)} skipped" if acq.skipped else "")
        + (f" (more poses measured: {acq.more_poses})" if acq.more_poses else ""),
        f"fit: {'converged' if fitd['converged'] else 'NOT CONVERGED'}, effects "
        f"{', '.join(fitd['effects'])}; residual RMS {fitd['rms_mm']:.4f} mm "
        f"(max {fitd['max_mm']:.4f}), measured noise RMS {_mm(fitd['noise_rms_mm'])} mm "
        f"(stated {_mm(fitd.get('stated_noise_rms_mm'))}), chi2/dof "
        f"{fitd['chi2_dof'] if fitd['chi2_dof'] is None else round(fitd['chi2_dof'], 3)}"
        + (f" ({round(fitd['chi2_dof_with_calibration'], 3)} with the camera calibration's "
           "covariance)" if fitd.get("chi2_dof_with_calibration") is not None else ""),
    ]
    for text in fitd["unidentifiable"]:
        lines.append(f"  unidentifiable: {text}")
    lines += reference_summary_lines(run)  # joints calibrated, reference check
    robot_time = format_robot_time({"robot_time_s": run.robot_time_s, "plan": run.plan})
    if robot_time:
        lines.append(robot_time)
    for item in acq.skipped[:10]:
        lines.append(f"  skipped {item.phase} pose {item.index}: {item.reason}")
    rows = run.offsets
    names = [joint_display_name(j, row.label) for j, row in enumerate(rows)]
    width = max([6, *(len(name) + 2 for name in names)])
    status = {int(j["joint"]): j for j in outcome.get("joints", [])}
    lines += ["", f"  {'joint':<{width}}{'old [deg]':>12}{'correction':>21}{'+/- sigma':>11}"
                  f"{'new [deg]':>12}  pushed" + ("  status" if status else "")]
    for name, row in zip(names, rows, strict=True):
        joint = status.get(row.joint, {})
        corr = "-" if row.correction_deg is None else f"{row.correction_deg:+.5f}"
        corr += SOURCE_MARK.get(str(joint.get("source")), "")
        sig = "-" if row.sigma_deg is None else f"{row.sigma_deg:.5f}"
        pushed = "yes" if row.pushed else ("no: " + row.note if row.note else "no")
        lines.append(f"  {name:<{width}}{row.old_deg:>12.5f}{corr:>21}"
                     f"{sig:>11}{row.new_deg:>12.5f}  {pushed}"
                     + (f"  {joint_status_text(joint, row.note)}" if joint else ""))
    lines.append("")
    if outcome:
        lines.append(f"controller: {outcome['controller']}")
    lines.append(_push_line({"push": run.push.to_dict(), "robot": robot,
                             "run_dir": run.run_dir, "archive": outcome.get("archive")}))
    if run.verify:
        verify_line = _verify_line(run.verify)
        if outcome and outcome.get("verdict") == "ROLLED_BACK":  # no longer the robot's
            verify_line = verify_line.replace(
                "verify:", "verify (of the offsets since rolled back, no longer in the "
                "controller):", 1)
        lines.append(verify_line)
    truth = run.truth
    if truth:
        errors = ", ".join(
            f"{names[j] if j < len(names) else f'J{j + 1}'} "
            + ("-" if e is None else f"{e:+.5f}")
            for j, e in enumerate(truth["joint_offsets_error_deg"]))
        lines.append(f"truth (simulation): fitted - true [deg]: {errors}")
        inside = [w for w in truth["within_3_sigma"] if w is not None]
        if inside:
            lines.append(f"  {sum(inside)} of {len(inside)} identifiable offsets within 3 sigma"
                         f", largest error {truth['max_abs_error_deg']:.5f} deg")
    report = run.files.get("report")
    if report:
        lines.append(f"report: {report}")
    if outcome.get("next_command"):
        lines.append(f"next: {outcome['next_command']}")
    return "\n".join(lines)


def plan_line(plan: JsonObject, acquisition: JsonObject) -> str:
    """The summary's plan line: the poses planned and, when the model failed on them and
    the plan grew (more_poses.py), what it grew to, so it never disagrees with the
    "measured" line below it."""
    source = (f"{plan.get('criterion', '?')}-optimal from {plan.get('n_candidates', '?')} "
              "candidates")
    if acquisition.get("more_poses"):
        planned = plan.get("predicted_robot_time_s")
        time = (f" (predicted robot time of measure + verify {planned['total']:.1f} s)"
                if isinstance(planned, Mapping) else "")
        return (f"plan: {plan['n_poses']} poses ({source}), grown to "
                f"{acquisition['n_planned']} fit and {plan['n_verify']} verification poses "
                f"when the model did not explain the first {plan['n_poses']}{time}")
    return f"plan: {plan['n_poses']} poses ({source}), {plan['n_verify']} verification poses"


SOURCE_MARK = {"hold": " (held)", "prior": " (prior)"}
"""How a value restated from a hold or a prior is marked wherever it is shown."""


def joint_status_text(joint: JsonObject, said: str = "") -> str:
    """One joint of the outcome in words: `calibrated, verified` / `NOT CALIBRATED: why`
    (without the why when `said`: the row already gives it)."""
    if joint.get("status") != "calibrated":
        return "NOT CALIBRATED" + ("" if said else ": " + str(
            joint.get("reason") or "not determined by the data"))
    done = ("verified" if joint.get("verified") is True else
            "pushed, NOT verified" if joint.get("pushed") or joint.get("applied_on_host")
            else "not pushed")
    zero = joint.get("zero_from")
    if isinstance(zero, Mapping) and zero.get("reference_zero") != "measured":
        why = ("its zero as at that run, not measured against a surveyed frame"
               if zero.get("reference_zero") == "as_found" else
               "whether that run calibrated it is not recorded")
        return f"restored to the cell reference of {zero.get('reference_run')} ({why}), {done}"
    if done == "not pushed":
        return "calibrated (not pushed)"
    return f"calibrated, {done}"


def _mm(value: float | None) -> str:
    return "-" if value is None else f"{value:.4f}"


def _push_line(document: JsonObject) -> str:
    """The summary's push line: what happened to the controller and how to undo it."""
    push = document["push"]
    status = push["status"]
    if status == APPLIED_ON_HOST:
        return ("push: applied on the host for this session only (UR has no writable zero "
                f"offsets); load {push['exports']['yaml']} in your UR/ROS setup")
    if status == "pushed" and document["robot"].get("driver") == "replay":
        return ("push: replayed from the recording (nothing written to a robot; the "
                "recorded run's push is what reached its controller)")
    if status == "pushed":
        if document["robot"].get("sim"):
            undo = "simulated controller: nothing to roll back after the run"
        else:
            undo = f"undo with {rollback_command(document['run_dir'], document.get('archive'))}"
        rollback_id = push.get("rollback_id")
        what = (f"rollback id {rollback_id}" if rollback_id is not None
                else "recovered after an interruption, no rollback id")
        return f"push: written ({what}; {undo})"
    if status == "refused":
        return f"push: REFUSED: {push['reason']}"
    if status == "disabled":
        return ("push: not requested (--no-push); the controller is unchanged"
                + (f"; offsets for your UR/ROS setup: {push['exports']['yaml']}"
                   if push.get("exports") else ""))
    if status == "rolled_back":
        return ("push: not repeated: this run's push was rolled back (the controller has its "
                "previous offsets); resume with --push or --force to push again")
    return "push: nothing to push (no identifiable joint offset)"


def _verify_line(verify: JsonObject) -> str:
    """The summary's verification line: the chi-square test (statistic, dof, p-value, the
    false-FAIL rate alpha) and the station tolerance. With nothing pushed it checks the model
    on fresh poses (no PASS: no offsets were verified)."""
    poses = (f"{verify['n_planned']} fresh poses ({verify['n_measured']} samples)"
             if verify["n_measured"] > verify["n_planned"]  # dual_loop: two targets a pose
             else f"{verify['n_measured']} fresh poses")
    p_value = verify.get("p_value")
    p_text = _p_value(p_value)
    test = (f"chi2 {_num(verify.get('statistic'))} on {verify.get('dof')} dof, p "
            f"{p_text if p_text.startswith('>') else '= ' + p_text} "
            f"(FAIL if p < alpha = {verify.get('alpha')})")
    tolerance = verify.get("tolerance_mm")
    test += ("; tolerance: none" if tolerance is None
             else f"; tolerance RMS <= {tolerance:g} mm")
    verdict = verify.get("verdict", "PASS" if verify.get("passed") else "FAIL")
    why = f" ({verify['reason']})" if verify.get("reason") else ""
    if not verify.get("pushed", True):
        return (f"model check on fresh poses (nothing pushed): {poses}: RMS with the fitted "
                f"model {_mm(verify['rms_after_mm'])} mm (max {_mm(verify['max_after_mm'])}), "
                f"with the controller's offsets as they are {_mm(verify['rms_before_mm'])} mm; "
                f"{test}: the model "
                + ("explains them" if verify["passed"] else "does NOT explain them" + why))
    return (f"verify: {poses}: RMS before (old offsets) {_mm(verify['rms_before_mm'])} mm "
            f"(max {_mm(verify['max_before_mm'])}), after {_mm(verify['rms_after_mm'])} mm "
            f"(max {_mm(verify['max_after_mm'])}); {test}: {verdict}{why}")


def _p_value(p: float | None) -> str:
    """A p-value to 3 digits that never rounds up to a bare 1 (or down to 0)."""
    if p is None:
        return "-"
    text = f"{p:.3g}"
    if text == "1" and p < 1.0:
        return "> 0.999"
    return text if float(text) > 0.0 or p == 0.0 else f"{p:.1e}"


def _num(value: float | None) -> str:
    return "-" if value is None else f"{value:.2f}"
