"""A calibration run and its cell reference (`hostpc calibrate --reference FILE`), and the
frames it holds known: which reference the run uses (a new run: the file given; a resume:
the run folder's copy, replaced by `--reference FILE` or dropped by `--reference none`),
which joints the run can calibrate with its frames (said before anything moves), the
priors its fit gets, the check of the reference after the fit (hostpc.calibrate.
reference_check) and the push it refuses when a referenced frame moved.

A resume may change the known frames (`--known`) and the reference: the measured samples
are refitted (nothing is measured again); the change is journaled and the run's cell
rewritten, so a later resume keeps it.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from hostpc.calibrate.joint_status import prior_dominated
from hostpc.calibrate.journal import Journal
from hostpc.calibrate.journal_events import Note
from hostpc.calibrate.push import PushPlan, joint_display_name
from hostpc.calibrate.reference import (
    REFERENCE_FILE,
    RIG_FRAMES,
    CellReference,
    FramePrior,
    check_reference_matches,
    frame_priors,
    load_reference,
)
from hostpc.calibrate.reference_check import ReferenceCheck, check_reference
from hostpc.calibrate.refusals import PushRefusal, resume_with
from hostpc.calibrate.run_header import RunHeader
from hostpc.calibrate.run_result import RunResult
from hostpc.dataset import Dataset
from hostpc.errors import InputError
from hostpc.files import write_json_atomic
from hostpc.fitting.priors import (
    analyse_with_constraints,
    constraints_for,
    with_constraints,
    with_prior_blocks,
)
from hostpc.json_object import JsonObject
from hostpc.methods.base import Method, Plan, Progress, RunSettings
from hostpc.methods.cell import Cell
from hostpc.model.joint_offsets import PushTable

NO_REFERENCE = "none"


def choose_reference(run_dir: Path, option: str | None, *, resume: bool, method: str,
                     robot_model: str, robot_serial: str | None
                     ) -> tuple[CellReference | None, bool]:
    """(the reference this run uses, True if that changes the run folder's copy).

    option: `--reference` (None: a new run has none, a resume keeps its copy; "none":
    none). A file is validated and must match the run's method, robot model and (if
    known) serial: InputError, one line, before anything moves."""
    copy = run_dir / REFERENCE_FILE
    if option is None:
        if resume and copy.is_file():
            return load_reference(copy), False
        return None, False
    if option == NO_REFERENCE:
        return None, resume and copy.is_file()
    reference = load_reference(option)
    check_reference_matches(reference, method=method, robot_model=robot_model,
                            robot_serial=robot_serial, where=f"--reference {option}")
    return reference, True


def record_reference_choice(run_dir: Path, journal: Journal, reference: CellReference | None,
                            changed: bool, option: str | None, progress: Progress) -> None:
    """Write (or remove) the run folder's copy of the reference and journal a change."""
    if not changed:
        return
    copy = run_dir / REFERENCE_FILE
    if reference is None:
        copy.unlink(missing_ok=True)
        journal.append(Note("reference dropped (--reference none)"))
        progress.message("reference: none (dropped on this resume)")
        return
    write_json_atomic(copy, reference.to_dict())
    journal.append(Note("reference loaded", reference=str(option),
                        recorded=reference.recorded))
    progress.message(f"reference: {option} (recorded {reference.date} on "
                     f"{reference.robot_serial or reference.robot_model}; frames "
                     f"{', '.join(f.name for f in reference.frames)})")


def resume_known(cell: Cell, known: tuple[str, ...] | None, header: RunHeader,
                 journal: Journal, progress: Progress) -> tuple[Cell, RunHeader]:
    """The resumed run's cell with `--known` applied (None: unchanged): the samples are
    refitted with the new known set, which is journaled and kept in run.json (the header
    returned)."""
    if known is None or tuple(known) == tuple(cell.known):
        return cell, header
    cell = dataclasses.replace(cell, known=tuple(known))
    header = dataclasses.replace(header, cell=cell.to_dict())
    journal.write_header(header.to_dict())
    journal.append(Note("known frames changed on resume", known=tuple(known)))
    progress.message(f"resume with known frames: {', '.join(known) or 'none'} (the measured "
                     "samples are refitted)")
    return cell, header


def reference_priors(reference: CellReference | None, dataset: Dataset,
                     settings: RunSettings) -> tuple[Dataset, list[FramePrior]]:
    """The dataset with the reference's frames as prior blocks on the frames its model
    estimates (a frame the cell holds known keeps its surveyed value)."""
    if reference is None:
        return dataset, []
    from hostpc.model.problem import build_problem

    estimated = build_problem(dataset, settings.effects, plugins=settings.plugins).frame_names
    priors = frame_priors(reference, dataset, estimated)  # a camera frame needs its rig
    return with_prior_blocks(dataset, [p.block() for p in priors]), priors


def check_run_reference(result: Any, priors: Sequence[FramePrior], settings: RunSettings,
                        progress: Progress) -> ReferenceCheck | None:
    """The reference check of the run's fit (None without a reference)."""
    if not priors:
        return None
    progress.stage("reference check")
    check = check_reference(result, priors, effects=settings.effects,
                            plugins=settings.plugins, loss=settings.loss)
    for frame in check.frames:
        state = "MOVED" if frame.moved else "holds"
        progress.message(f"reference check: {frame.frame} {state} (D^2 {frame.distance2:.1f}"
                         f" for {frame.dof} dof, limit {frame.threshold:.1f})")
    return check


def moved_line(check: ReferenceCheck, reference: CellReference, run_dir: Path) -> str:
    """The one line that names the moved frame and the next command."""
    cause = check.cause()
    assert cause is not None
    least = "at least " if cause.confounded else ""  # a part of it looks like a joint
    return (f"the {cause.frame} frame moved {least}{cause.size_text()} since the reference of "
            f"{reference.date}: nothing pushed (offsets fitted against a moved reference "
            "are wrong); put it back and measure again, or, if the robot's zeros are good, "
            f"re-record the reference: hostpc calibrate --resume {run_dir} --reference none "
            f"&& hostpc reference record --run {run_dir} --out cell_ref.json")


def refuse_if_moved(plan: PushPlan, check: ReferenceCheck | None,
                    reference: CellReference | None, run_dir: Path) -> PushPlan:
    """The push plan, refused (even with --force) when a referenced frame moved."""
    if check is None or not check.moved or reference is None:
        return plan
    line = moved_line(check, reference, run_dir)
    return dataclasses.replace(plan, refused=line, refusal=PushRefusal(
        line, "reference_moved", resume_with("--reference", "none")))


def reference_check_block(check: ReferenceCheck | None, reference: CellReference | None,
                          run_dir: Path) -> JsonObject | None:
    """The result's `reference_check` block (None without a reference)."""
    if reference is None:
        return None
    block: JsonObject = {"reference": str(run_dir / REFERENCE_FILE),
                         "recorded": reference.recorded,
                         "robot_serial": reference.robot_serial}
    if check is not None:
        block.update(check.to_dict())
        if check.moved:
            block["message"] = moved_line(check, reference, run_dir)
    return block


def reference_summary_lines(run: RunResult) -> list[str]:
    """The summary's lines for the joints the run can calibrate and the reference check."""
    lines = []
    joints = run.plan.get("joints")
    if joints:
        lines.append(f"joints: {joints['text']}")
    block = run.reference_check
    if block:
        if block.get("moved"):
            lines.append(f"reference check: {block['message']}")
        else:
            frames = ", ".join(f["frame"] for f in block.get("frames", []))
            lines.append(f"reference check: {frames or 'no frame'} still as recorded on "
                         f"{str(block['recorded'])[:10]} (false-alarm rate "
                         f"{block.get('alpha', 0.0):g})")
    return lines


# ------------------------------------------------------------------ which joints


def joint_coverage(method: Method, plan: Plan, settings: RunSettings, cell: Cell,
                   reference: CellReference | None) -> JsonObject:
    """Which joints the planned poses calibrate with this run's frames: from the
    measurements (with the known frames), from the reference, or not at all (and why):
    the plan's `joints` info, in its JSON form (run.json, result.json).
    Linear analysis at the nominal model of the fit poses; nothing moves. Derived again
    from the run's current settings on every start and resume (a resume may change the
    reference and the known frames, while it reuses the plan made at the run's start), so
    it predicts its own sigmas (design.parameter_covariance, as the plan does) to tell a
    joint its --prior decides."""
    from hostpc.model.measurements.predict import predict
    from hostpc.model.problem import build_problem
    from hostpc.planning.design import parameter_covariance

    user = with_constraints(method.design_dataset(plan.q), settings.priors, settings.hold)
    dataset, priors = reference_priors(reference, user, settings)
    problem = build_problem(dataset, settings.effects, plugins=settings.plugins)
    _, J = predict(problem, np.zeros(problem.layout.size), jacobian=True)
    assert J is not None
    A = np.einsum("nij,njp->nip", problem.sqrt_information, J).reshape(-1, problem.layout.size)
    names, units = tuple(problem.layout.names), tuple(problem.layout.units)
    frames = problem.frame_names
    # bare: the measurements with the user's --hold/--prior; full: also the reference's
    # frames. A joint only `full` resolves is the reference's; one the user's constraint
    # resolves is the measurements' (with that constraint), reference or not.
    user_constraints = constraints_for(user.extra_fields, names, units)
    bare, _ = analyse_with_constraints(A, names, units, user_constraints, frames=frames)
    constraints = constraints_for(dataset.extra_fields, names, units)
    full, _ = analyse_with_constraints(A, names, units, constraints, frames=frames)
    held_data = ({d.fixed: d for d in analyse_with_constraints(
        A, names, units, None, frames=frames)[0].null_directions}
        if user_constraints is not None else {})
    n = int(np.asarray(plan.q).shape[1])
    table = PushTable.for_controller(n, problem.context.joint_labels)
    offsets = table.names
    labels = [joint_display_name(j, label) for j, label in enumerate(table.labels)]
    held_bare = {d.fixed: d for d in bare.null_directions}
    held_full = {d.fixed: d for d in full.null_directions}
    user_held = ({n for n, h in zip(names, user_constraints.held, strict=True) if h}
                 if user_constraints is not None else set())
    prior_sigma = ({p.name: float(p.sigma) for p in user_constraints.priors}
                   if user_constraints is not None else {})
    # each parameter's predicted sigma with the priors' rows, held or unidentifiable: NaN
    rows = A if constraints is None else np.vstack([A, constraints.jacobian(A.shape[1])])
    sigma = np.sqrt(np.diag(parameter_covariance(rows, ~full.fixed)))
    measured, referenced, resolved, held, from_prior = [], [], [], [], []
    missing: dict[str, str] = {}
    held_joints, by_user = [], []
    for j, (label, name) in enumerate(zip(labels, offsets, strict=True)):
        if name in user_held:  # joint_status's sources: hold, prior, data, none
            held.append(label)
            held_joints.append(j + 1)
        elif name in prior_sigma and prior_dominated(sigma[names.index(name)],
                                                     prior_sigma[name]):
            from_prior.append(label)
        elif name not in names:
            missing[label] = "not in the model"
        elif name in held_full:
            others = [p.split(".", 1)[0] for p in held_full[name].parameters[1:]]
            frame = next((o for o in others if o in frames), None)
            missing[label] = (f"not separable from the {frame} frame: mark it known "
                              "(--known) or load a cell reference (--reference FILE)"
                              if frame else "not separable from other parameters")
            if len(held_full[name].parameters) == 1:  # physics: nothing sees this joint
                missing[label] = ("it has no effect on these measurements (e.g. a probe tip "
                                  "or reflector on its axis): no frame can give it")
            if (reference is not None and frame in RIG_FRAMES and reference.frame(frame)
                    and not reference.rig_matches(dataset)):
                missing[label] = (f"the reference's {frame} frame was measured with another "
                                  "stereo rig calibration: give its rig, --rig FILE (hostpc "
                                  "reference record writes it beside the reference)")
        elif name in held_bare:
            referenced.append(label)
            resolved.append(name)
        else:
            measured.append(label)
            if name in held_data:  # the user's --hold/--prior on a frame separates it
                others = [p.split(".", 1)[0] for p in held_data[name].parameters[1:]]
                frame = next((o for o in others if o in frames), None)
                by_user.append(f"{label} with --hold/--prior on {frame or 'other parameters'}")
    known = ", ".join(cell.known) or "none"
    text = f"{', '.join(measured) or 'none'} from the measurements (known frames: {known}"
    text += f"; {', '.join(by_user)})" if by_user else ")"
    if referenced:
        text += (f"; {', '.join(referenced)} from the reference of {reference.date} "  # type: ignore[union-attr]
                 f"({', '.join(p.frame for p in priors)}: valid only while those frames "
                 "sit as recorded; the reference check tests it)")
    if held:
        text += f"; {', '.join(held)} held at nominal by --hold (not calibrated)"
    if from_prior:
        text += (f"; {', '.join(from_prior)} from its --prior, not the data (not "
                 "calibrated)")
    if missing:
        text += "; cannot calibrate " + "; ".join(f"{k} ({v})" for k, v in missing.items())
    elif not held and not from_prior:
        text += "; every joint calibrated"
    return {"from_measurements": measured, "from_reference": referenced,
            "resolved_by_reference": resolved, "held": held, "held_joints": held_joints,
            "from_prior": from_prior,
            "not_calibrated": missing, "text": text}


def with_joint_coverage(plan: Plan, method: Method, settings: RunSettings, cell: Cell,
                        reference: CellReference | None, progress: Progress) -> Plan:
    """The plan with its `joints` info (joint_coverage), said before anything moves."""
    try:
        coverage = joint_coverage(method, plan, settings, cell, reference)
    except (InputError, ValueError, np.linalg.LinAlgError) as exc:
        coverage = {"text": f"not analysed ({exc})"}
    progress.message(f"joints: {coverage['text']}")
    info = {**plan.info, "joints": coverage}
    held = set(coverage.get("held_joints", []))
    sigmas = info.get("predicted_joint_sigma_deg")
    if held and isinstance(sigmas, list):  # a held joint is not estimated: no sigma
        info["predicted_joint_sigma_deg"] = [None if j + 1 in held else s
                                             for j, s in enumerate(sigmas)]
    resolved = set(coverage.get("resolved_by_reference", []))
    fixed = list(info.get("structural_fixed", []))
    if resolved and len(fixed) == len(info.get("structural_unidentifiable", [])):
        keep = [k for k, name in enumerate(fixed) if name not in resolved]
        info["structural_unidentifiable"] = [info["structural_unidentifiable"][k]
                                             for k in keep]
        info["structural_fixed"] = [fixed[k] for k in keep]
    return dataclasses.replace(plan, info=info)
