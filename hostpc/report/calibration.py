"""The report of a calibration run (``RUN/report.html``): the result first, then the diagnosis.

Read from the run's result document (``result.json``, hostpc.calibrate.summary), in this order:
the verdict (the result's ``outcome`` block when it has one: its headline, what the
controller holds, the next command; a per-joint table of calibrated / not calibrated, the
source data / hold / prior and why not; older results: PASS / FAIL, pushed or not and
why), the offsets table (joint, old, correction (a hold or prior value marked), sigma,
new, pushed; for a simulated run also the true zero error and fitted - true), the
verification statistic, the comparison with the simulator's truth, a short account of the
fit and push, and then the diagnosis of the fitted model (hostpc.report.html) with every
effect parameter's size (against the truth for a simulated run).

Older result documents lack some keys (e.g. the ``verify`` statistic before its chi-square
test): what is absent is left out, never shown as a placeholder.

    from hostpc.report import write_calibration_report
    write_calibration_report("run/report.html", result_document, diagnosis, truth)
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from hostpc.diagnostics import Diagnosis
from hostpc.report.html import diagnosis_body
from hostpc.report.markup import escape, page, prose, table
from hostpc.report.run_advice import run_advice

Document = Mapping[str, Any]

# the verification keys a result document may hold, in display order: (key, label, format)
VERIFY_ROWS = (
    ("verdict", "verdict", "text"),
    ("statistic", "test statistic", "g4"),
    ("dof", "degrees of freedom", "int"),
    ("p_value", "p-value (a statistic this large if the offsets are right)", "p"),
    ("alpha", "false-FAIL rate (alpha)", "p"),
    ("n_poses", "fresh poses", "int"),
    ("n_planned", "poses planned", "int"),
    ("n_measured", "samples measured", "int"),
    ("rms_mm", "RMS after the push [mm]", "f4"),
    ("tolerance_mm", "task-space tolerance [mm]", "tol"),
    ("rms_before_mm", "RMS with the old offsets [mm]", "f4"),
    ("max_before_mm", "max with the old offsets [mm]", "f4"),
    ("rms_after_mm", "RMS with the fitted offsets [mm]", "f4"),
    ("max_after_mm", "max with the fitted offsets [mm]", "f4"),
    ("noise_rms_mm", "noise RMS the fit measured [mm]", "f4"),
    ("stated_noise_rms_mm", "noise RMS the covariances state [mm]", "f4"),
    ("factor", "pass if RMS after <= factor x noise: factor", "g4"),
    ("threshold_mm", "that bound [mm]", "f4"),
    ("reason", "why it failed", "text"),
)
# keys shown only when their twin is absent (the chi-square verify holds both)
TWINS = {"rms_mm": "rms_after_mm", "n_planned": "n_poses"}
# the RMS rule of older versions: its keys describe the verdict only without a statistic
RMS_RULE_KEYS = ("factor", "threshold_mm", "noise_rms_mm")


def _value(value: Any, kind: str) -> str | None:
    """A result value as text, or None when there is nothing to show."""
    if value is None:
        return "none set" if kind == "tol" else None
    if kind == "text":
        return escape(value) if str(value) else None
    if kind == "int":
        return str(int(value))
    if kind == "p":
        return f"{float(value):.3g}"
    if kind in ("f4", "tol"):
        return f"{float(value):.4f}"
    return f"{float(value):.4g}"


def joint_name(index: int, label: str) -> str:
    """J1..Jn, or a kinematic tree's label (``left.q3``): as the summary names joints."""
    return label if label and label != f"q{index + 1}" else f"J{index + 1}"


def _verified(result: Document) -> tuple[bool | None, bool]:
    """(passed or None without a verification, whether it verified pushed offsets)."""
    verify = result.get("verify") or None
    if not verify:
        return None, False
    pushed = bool(verify.get("pushed", result.get("push", {}).get("status") == "pushed"))
    if "verdict" in verify:
        return str(verify["verdict"]).upper() == "PASS", pushed
    if "passed" in verify:
        return bool(verify["passed"]), pushed
    return None, pushed


OUTCOME_CSS = {"PASS": "good", "FAIL": "bad", "REFUSED": "bad", "JOINTS_MISSING": "bad",
               "ERROR": "bad", "NOT_PUSHED": "neutral", "NOT_VERIFIED": "neutral",
               "ROLLED_BACK": "neutral"}
SOURCE_MARK = {"hold": " (held)", "prior": " (prior)"}
"""A value restated from a hold or a prior, marked wherever it is shown."""


def _outcome_verdict(outcome: Document, result: Document) -> tuple[str, str, list[str]]:
    """The verdict box of a result with an outcome block: its headline, what the
    controller holds, the next command; nothing re-derived."""
    lines = [f"Controller: {outcome.get('controller')}."]
    reason = (result.get("push") or {}).get("reason")
    if outcome.get("verdict") == "REFUSED" and reason:
        lines.append(f"Push refused: {reason}")
    if outcome.get("next_command"):
        lines.append(f"Next: {outcome['next_command']}")
    if "exit_code" in result:
        lines.append(f"Exit code {result['exit_code']}.")
    return (OUTCOME_CSS.get(str(outcome.get("verdict")), "neutral"),
            str(outcome.get("headline") or outcome.get("verdict")), lines)


def outcome_table(result: Document) -> str:
    """Per joint: calibrated or not, from where, pushed, verified, why not, the fix."""
    joints = (result.get("outcome") or {}).get("joints") or []
    if not joints:
        return ""
    rows = []
    for j, row in enumerate(joints):
        def flag(value: Any) -> str:
            return "-" if value is None else ("yes" if value else "NO")

        zero = row.get("zero_from")
        status = ("calibrated" if row.get("status") == "calibrated"
                  else '<span class="significant">NOT CALIBRATED</span>')
        if (row.get("status") == "calibrated" and isinstance(zero, Mapping)
                and zero.get("reference_zero") != "measured"):  # outcome.py: as found
            status = escape(f"restored to the cell reference of {zero.get('reference_run')} "
                            "(its zero as at that run, not measured)")
        pushed = "host session only" if row.get("applied_on_host") else flag(row.get("pushed"))
        rows.append([escape(joint_name(j, str(row.get("label", "")))), status,
                     escape(row.get("source", "")), pushed,
                     flag(row.get("verified")), prose(row.get("reason") or ""),
                     prose(row.get("fix") or "")])
    return ("<h2>Joints</h2>" + table(("joint", "status", "source", "pushed", "verified",
                                       "why not calibrated", "what would determine it"),
                                      rows, table_id="joints", text_columns=(1, 2, 5, 6)))


def verdict(result: Document) -> tuple[str, str, list[str]]:
    """(css class good/bad/neutral, headline, explanation sentences) of a run's result:
    its outcome block when it has one (outcome.py), else read from an older result."""
    if isinstance(result.get("outcome"), Mapping):
        return _outcome_verdict(result["outcome"], result)
    push = result.get("push") or {}
    status = push.get("status")
    passed, verified_push = _verified(result)
    lines: list[str] = []
    if push.get("reason"):
        lines.append(f"Push refused: {push['reason']}")
    if status == "pushed":
        where = ("applied on the host for this session only (the robot keeps no zero "
                 "offsets: load the exported file in its own software)"
                 if push.get("on_controller") is False else "written to the controller")
        if push.get("rollback_id"):
            where += f", rollback id {push['rollback_id']}"
        lines.insert(0, f"Offsets {where}.")
        if passed is None:
            head, css = "PUSHED, NOT VERIFIED: no verification poses were measured", "neutral"
        elif passed:
            head, css = "PASS: offsets pushed and verified on fresh poses", "good"
        else:
            head, css = "FAIL: the pushed offsets failed verification on fresh poses", "bad"
    elif status == "refused":
        head, css = "NOT PUSHED: the guard rails refused the push", "bad"
    elif status == "disabled":
        head, css = "NOT PUSHED: --no-push (the controller is unchanged)", "neutral"
    elif status == "rolled_back":
        head, css = "NOT PUSHED: this run's push was rolled back", "neutral"
    elif status is None:
        head, css = "NO PUSH RECORDED in this result", "neutral"
    else:
        head, css = "NOT PUSHED: no identifiable joint offset to push", "neutral"
    if passed is not None and not verified_push:
        lines.append("Model check on fresh poses (nothing pushed): the fitted model "
                     + ("explains them." if passed else "does NOT explain them."))
    if "exit_code" in result:
        lines.append(f"Exit code {result['exit_code']}.")
    return css, head, lines


def offsets_table(result: Document) -> str:
    """The offsets table (degrees): with the simulator's truth when the result has it."""
    rows_in = (result.get("offsets") or {}).get("joints") or []
    truth = result.get("truth") or None
    header = ["joint", "old [deg]", "correction [deg]", "+/- sigma [deg]", "new [deg]",
              "pushed"]
    if truth:
        header += ["true zero error [deg]", "fitted - true [deg]", "within 3 sigma"]
    sources = {int(j.get("joint", 0)): str(j.get("source"))
               for j in (result.get("outcome") or {}).get("joints") or []}
    rows = []
    for j, row in enumerate(rows_in):
        def deg(key: str, signed: bool = False, source: Mapping[str, Any] = row) -> str:
            value = source.get(key)
            return "-" if value is None else (f"{value:+.5f}" if signed else f"{value:.5f}")

        mark = SOURCE_MARK.get(sources.get(int(row.get("joint", j + 1)), ""), "")

        pushed = "yes" if row.get("pushed") else (
            "no: " + row["note"] if row.get("note") else "no")
        cells = [escape(joint_name(j, row.get("label", ""))), deg("old_deg"),
                 deg("correction_deg", True) + mark, deg("sigma_deg"), deg("new_deg"),
                 escape(pushed)]
        if truth:
            true = _at(truth.get("zero_errors_deg"), j)
            error = _at(truth.get("joint_offsets_error_deg"), j)
            inside = _at(truth.get("within_3_sigma"), j)
            cells += ["-" if true is None else f"{true:+.5f}",
                      "-" if error is None else f"{error:+.5f}",
                      "-" if inside is None else
                      ("yes" if inside else '<span class="significant">NO</span>')]
        rows.append(cells)
    if not rows:
        return "<p>This result holds no offsets.</p>"
    return table(header, rows, table_id="offsets", text_columns=(5,))


def _at(values: Any, index: int) -> Any:
    return values[index] if isinstance(values, list) and index < len(values) else None


def verification_section(result: Document) -> str:
    """The verification statistic and its numbers (whatever the document holds)."""
    verify = result.get("verify") or None
    if not verify:
        return ("<p>No verification: no fresh poses were measured after the fit "
                "(<code>--verify-poses 0</code>, or the run ended before them).</p>")
    rows = []
    for key, label, kind in VERIFY_ROWS:
        if key not in verify or TWINS.get(key) in verify:
            continue
        if key in RMS_RULE_KEYS and "statistic" in verify:
            continue
        text = _value(verify[key], kind)
        if text is not None:
            rows.append((escape(label), text))
    passed, pushed = _verified(result)
    what = ("the pushed offsets on fresh poses" if pushed
            else "the fitted model on fresh poses (nothing was pushed: a model check)")
    outcome = "" if passed is None else (" passed" if passed else " FAILED")
    rolled = (result.get("outcome") or {}).get("rolled_back_at")
    if pushed and rolled:  # the verdict was of offsets the controller no longer has
        return (f"<p>ROLLED BACK at {escape(str(rolled))}: the verification below "
                f"({'PASS' if passed else 'FAIL' if passed is not None else 'none'}) was of "
                "the offsets this run pushed; they were rolled back, and the controller has "
                "its previous offsets again, so it no longer describes the robot.</p>"
                + table(("quantity", "value"), rows, table_id="verification"))
    return (f"<p>Verification of {what}{outcome}.</p>"
            + table(("quantity", "value"), rows, table_id="verification"))


def truth_section(result: Document) -> str:
    """The fitted zero offsets against the simulator's injected zero errors."""
    truth = result.get("truth") or None
    if not truth:
        return ""
    inside = [w for w in truth.get("within_3_sigma", []) if w is not None]
    largest = truth.get("max_abs_error_deg")
    text = (f"{sum(inside)} of {len(inside)} identifiable zero offsets are within 3 sigma of "
            "the simulator's truth" if inside else "No zero offset was identifiable")
    if largest is not None:
        text += f"; the largest error is {largest:.5f} deg"
    return (f'<h2>Against the simulator\'s truth</h2><p id="truth-summary">{escape(text)}. '
            "Per joint: the last three columns of the offsets table; effect sizes against "
            "their truth: Parameters below.</p>")


def fit_section(result: Document) -> str:
    """Plan, measurement and fit in a few rows."""
    fit = result.get("fit") or {}
    plan = result.get("plan") or {}
    acquisition = result.get("acquisition") or {}
    rows = []
    if plan:
        grown = (f" grown to {acquisition.get('n_planned', '-')} (the model did not explain "
                 f"the first {plan.get('n_poses', '-')})" if acquisition.get("more_poses")
                 else "")
        rows.append(("plan", f"{plan.get('n_poses', '-')} fit poses{grown}, "
                             f"{plan.get('n_verify', '-')} verification poses"))
    if acquisition:
        rows.append(("measured", f"{acquisition.get('n_measured', '-')} samples of "
                                 f"{acquisition.get('n_planned', '-')} planned poses, "
                                 f"{acquisition.get('n_skipped', 0)} skipped"))
    if fit:
        rows.append(("model", ", ".join(fit.get("effects", []))))
        rows.append(("converged", "yes" if fit.get("converged") else "NO"))
        if fit.get("chi2_dof") is not None:
            upper = fit.get("chi2_dof_upper")
            edge = f" (push refused above {upper:.3f})" if upper is not None else ""
            full = fit.get("chi2_dof_with_calibration")  # what the push tested, if any
            rows.append(("chi2/dof", f"{fit['chi2_dof']:.3f}" + ("" if full is not None
                                                                else edge)))
            if full is not None:
                rows.append(("chi2/dof with the camera calibration's covariance",
                             f"{full:.3f}{edge}"))
        if fit.get("rms_mm") is not None:
            rows.append(("residual RMS / max [mm]",
                         f"{fit['rms_mm']:.4f} / {fit.get('max_mm', float('nan')):.4f}"))
        for text in fit.get("unidentifiable", []):
            rows.append(("unidentifiable", text))
    if not rows:
        return ""
    return "<h2>Fit</h2>" + table(("quantity", "value"),
                                  [(escape(k), prose(v)) for k, v in rows], table_id="fit",
                                  text_columns=(1,))


def render_calibration_html(result: Document, diagnosis: Diagnosis | None = None,
                            truth: Mapping[str, Any] | None = None) -> str:
    """The calibration report as one HTML string.

    result: the run's result document (``result.json``); diagnosis: of the fitted model
    (``hostpc.diagnose`` on the run's dataset), or None to leave the diagnosis out; truth:
    the simulator's truth dict (simulated runs), for the effect sizes."""
    robot = result.get("robot") or {}
    name = robot.get("name", "robot")
    where = " (simulated controller)" if robot.get("sim") else (
        f" at {robot['address']}" if robot.get("address") else "")
    title = f"zerocal calibration: {result.get('method', 'run')} on {name}{where}"
    css, head, lines = verdict(result)
    explanation = "".join(f"<p>{prose(line)}</p>" for line in lines)
    known = ", ".join(result.get("known", [])) or "none (every frame estimated)"
    run_dir = result.get("run_dir")
    facts = (f"<p>Run folder <code>{escape(run_dir)}</code>; " if run_dir else "<p>") + \
        f"known frames: {escape(known)}.</p>"
    sections = [
        f"<h1>{escape(title)}</h1>",
        f'<div class="verdict {css}" id="verdict">{escape(head)}{explanation}</div>',
        facts,
        f"<h2>Offsets</h2>{offsets_table(result)}",
        outcome_table(result),
        f"<h2>Verification</h2>{verification_section(result)}",
        truth_section(result),
        fit_section(result),
        "<h2>Diagnosis of the fitted model</h2>",
    ]
    if diagnosis is None:
        sections.append("<p>Not diagnosed: run <code>hostpc diagnose</code> on the run's "
                        "dataset.json for the diagnosis.</p>")
    else:
        sections.append(diagnosis_body(diagnosis, truth, skip_parameters=("joint_offsets",),
                                       advice_sentences=run_advice(diagnosis, result)))
    return page(title, "\n".join(s for s in sections if s))


def write_calibration_report(path: str | Path, result: Document,
                             diagnosis: Diagnosis | None = None,
                             truth: Mapping[str, Any] | None = None) -> Path:
    """Write the calibration report (``render_calibration_html``) to ``path``."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(render_calibration_html(result, diagnosis, truth), encoding="utf-8")
    return path
