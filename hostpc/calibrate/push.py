"""Pushing compensated zero offsets to the controller, with guard rails, and rolling back.

Compensation (docs/conventions.md): a fitted joint offset `delta_i` means
`q_true = q_cmd + delta_i`, so the new zero offset is `o_i_new = o_i + delta_i`.

Guard rails:
- joints whose offset the fit holds fixed (unidentifiable: the data cannot tell it apart
  from a frame) or that are not in the model keep their offset, and the plan says why;
  so do joints held by `--hold` or determined by their `--prior` rather than by the data
  (joint_status.py: a value restated from a hold or a prior is never pushed as measured);
- the whole push is refused unless `force` if the fit did not converge, if the model does
  not explain the measurements (chi2/dof above its chi-square band at alpha = 1e-3: the
  band's upper edge is the chi-square upper 1e-3 quantile for the fit's dof, divided by the
  dof; a chi2/dof below the band is no reason to refuse), or if a pushed joint's correction
  exceeds `max_correction_deg` (default 2 deg). When the dataset declares a shared error
  (a `rig_uncertainty` block: the stereo rig's or the head camera's calibration and its
  covariance), the chi2 tested is the one with that covariance inside
  (`hostpc.fitting.shared_chi2`: the residuals against noise + floor + D S D^T, with the
  residual projector, same dof): a rig that errs within its stated covariance is no reason
  to refuse (docs/vision.md 3.3). A robust-loss fit is tested on the samples its loss keeps
  (hostpc.diagnostics.robust_kept: the outliers of diagnose's test left out);
- the intent (previous and new offsets, time) is saved durably in the run folder
  (`push.json`, status "intent", and the journal's `push_intent` event) BEFORE the
  controller is written, then the result (status "pushed", the controller's rollback id);
  so a push cut between the two is recognised from the controller's offsets (equal to the
  new ones: pushed; equal to the previous ones: not pushed) and `hostpc rollback --run DIR`
  can undo it either way;
- the controller's word is never taken for the push: the previous offsets recorded are
  the ones read before the write, and the offsets are read back after it; a controller
  that holds other ones than pushed or names other previous ones fails the push
  (PushMismatch, exit 4) with the rollback to run.
"""

from __future__ import annotations

import dataclasses
import datetime as _dt
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from hostpc.calibrate.joint_status import joint_sources
from hostpc.calibrate.journal import Journal
from hostpc.calibrate.journal_events import Pushed, PushIntent, PushRecord, PushWritten
from hostpc.calibrate.refusals import PushRefusal, resume_with
from hostpc.calibrate.run_result import OffsetRow
from hostpc.calibrate.swaps import MAX_SWAP_LIMIT_DEG
from hostpc.diagnostics.adequacy import ADEQUACY_P_MIN, chi2_dof_upper
from hostpc.diagnostics.robust_kept import KeptSamples, kept_samples
from hostpc.errors import ControllerError, InputError
from hostpc.files import write_json_atomic
from hostpc.fitting import FitResult
from hostpc.fitting.result import FitVerdict
from hostpc.model.joint_offsets import PushTable
from hostpc.robots.base import RobotAdapter

PUSH_FILE = "push.json"
DEFAULT_MAX_CORRECTION_DEG = 2.0
# one adequacy rule for push and diagnose: the threshold lives in diagnostics
ADEQUACY_ALPHA: float = ADEQUACY_P_MIN
"""A fit whose chi2 exceeds the chi-square upper quantile at this level (chi-square p-value
below ADEQUACY_P_MIN) refuses the push."""
OFFSET_MATCH_TOLERANCE = 1e-9  # rad: controller offsets "equal" to a recorded set


def joint_display_name(index: int, label: str) -> str:
    """How the human output names joint `index` (0-based): the model's label of a
    kinematic tree's joint (`head.q1`, `left.q3`), else `J1`..`Jn`."""
    return label if label and label != f"q{index + 1}" else f"J{index + 1}"


@dataclass(frozen=True)
class PushPlan:
    """old / delta / new: (n,) rad (delta zero where not pushed); sigma: (n,) rad (NaN where
    not identified); pushed: (n,) bool; notes: per joint, why it is not pushed (or "");
    refused: why the guard rail refuses the whole push, or None; labels: the model's name
    of each joint (`q1`.., or a kinematic tree's `head.q1`, `left.q3`, ...)."""

    old: np.ndarray
    delta: np.ndarray
    new: np.ndarray
    sigma: np.ndarray
    pushed: np.ndarray
    notes: tuple[str, ...]
    refused: str | None = None
    max_correction_deg: float = DEFAULT_MAX_CORRECTION_DEG
    fitted: np.ndarray = field(default_factory=lambda: np.zeros(0))
    labels: tuple[str, ...] = ()
    chi2_dof_tested: float | None = None
    """The chi2/dof the adequacy guard tested when it is not the fit's plain one (the chi2
    with the dataset's shared error inside, `adequacy_chi2`), else None."""
    refusal: PushRefusal | None = None
    """`refused` as a structured value (which guard, which joint, the next command)."""

    @property
    def anything(self) -> bool:
        """True if at least one joint would change."""
        return bool(np.any(self.pushed))

    def display_names(self) -> list[str]:
        """Per joint, the name the human output uses (see `joint_display_name`)."""
        return [joint_display_name(j, self.labels[j] if j < len(self.labels) else "")
                for j in range(self.old.size)]

    def joints(self) -> tuple[OffsetRow, ...]:
        """Per joint, in degrees (for the result document and the summary)."""
        rows = []
        for j in range(self.old.size):
            fitted = float(self.fitted[j]) if self.fitted.size else float(self.delta[j])
            rows.append(OffsetRow(
                joint=j + 1,
                label=self.labels[j] if j < len(self.labels) else f"q{j + 1}",
                old_deg=math.degrees(float(self.old[j])),
                correction_deg=math.degrees(fitted) if np.isfinite(self.sigma[j]) else None,
                sigma_deg=(math.degrees(float(self.sigma[j]))
                           if np.isfinite(self.sigma[j]) else None),
                new_deg=math.degrees(float(self.new[j])),
                pushed=bool(self.pushed[j]),
                note=self.notes[j],
            ))
        return tuple(rows)


def plan_push(result: FitVerdict, old_offsets: np.ndarray,
              max_correction_deg: float = DEFAULT_MAX_CORRECTION_DEG, force: bool = False,
              dataset_file: str = "DIR/dataset.json",
              limits_deg: np.ndarray | None = None) -> PushPlan:
    """Decide what to push from a fit (see the module docstring); nothing is written.

    old_offsets: (n,) rad, the controller's offsets; dataset_file: the fit's dataset, named
    in the refusal of an inadequate model (what to run `hostpc diagnose` on); limits_deg:
    (n,) per-joint limit where a joint has its own (a declared swap, swaps.py), else
    max_correction_deg for every joint."""
    old = np.asarray(old_offsets, dtype=float)
    n = old.size
    names = result.names
    fitted = np.zeros(n)
    sigma = np.full(n, np.nan)
    pushed = np.zeros(n, dtype=bool)
    notes = []
    held = {d.fixed: d for d in result.unidentifiable}
    table = PushTable.for_controller(n, result.joint_labels)
    sources = joint_sources(result, n)  # a held or prior-dominated joint is never pushed
    for j, name in enumerate(table.names):
        if name not in names:
            notes.append("not in the model (joint_offsets not fitted)")
            continue
        k = names.index(name)
        if sources[j].source in ("hold", "prior"):
            notes.append(f"{sources[j].reason}; left unchanged")
            continue
        if result.fixed[k]:
            direction = held.get(name)
            reason = "unidentifiable with these frames and poses; left unchanged"
            if direction is not None and len(direction.parameters) > 1:
                others = ", ".join(direction.parameters[1:4])
                reason = f"unidentifiable (not separable from {others}); left unchanged"
            notes.append(reason)
            continue
        fitted[j] = result.x[k]
        sigma[j] = result.std[k]
        pushed[j] = True
        notes.append("")
    delta = np.where(pushed, fitted, 0.0)
    labels = table.labels
    limits = (np.full(n, float(max_correction_deg)) if limits_deg is None
              else np.asarray(limits_deg, float))
    tested = None if force else adequacy_chi2(result)
    refusal = None if tested is None else _refusal(result, delta, pushed, labels,
                                                   max_correction_deg, limits, dataset_file,
                                                   tested)
    return PushPlan(old=old, delta=delta, new=old + delta, sigma=sigma, pushed=pushed,
                    notes=tuple(notes), refused=None if refusal is None else refusal.reason,
                    max_correction_deg=max_correction_deg, fitted=fitted, labels=labels,
                    chi2_dof_tested=(tested.chi2_dof if tested is not None and tested.shared
                                     else None),
                    refusal=refusal)


@dataclass(frozen=True)
class AdequacyChi2:
    """The chi2/dof the guard tests and its dof; shared: it includes the dataset's shared
    error; kept: a robust-loss fit judged on the samples its loss keeps, else None."""

    chi2_dof: float
    dof: int
    shared: bool = False
    kept: KeptSamples | None = None


def adequacy_chi2(result: FitVerdict) -> AdequacyChi2:
    """What the guard tests. With a `rig_uncertainty` block in the fit's dataset: the chi2
    with the shared error's covariance inside (`FitVerdict.chi2_dof_with_calibration`: a
    live fit computes it, a saved fit carries it); else, for a robust-loss fit whose loss
    set samples aside, the chi2 over the samples it keeps (hostpc.diagnostics.robust_kept:
    a live fit computes it, a saved fit carries it in model_adequacy); else the fit's plain
    chi2/dof."""
    if not result.converged:
        return AdequacyChi2(result.chi2_dof, result.dof)
    full = result.chi2_dof_with_calibration
    if full is not None:
        return AdequacyChi2(float(full), result.dof, shared=True)
    kept = (kept_samples(result) if isinstance(result, FitResult)
            else getattr(result, "kept_samples", None))
    if isinstance(kept, KeptSamples):
        return AdequacyChi2(kept.chi2_dof, kept.dof, kept=kept)
    return AdequacyChi2(result.chi2_dof, result.dof)


def _refusal(result: FitVerdict, delta: np.ndarray, pushed: np.ndarray,
             labels: tuple[str, ...], max_correction_deg: float, limits: np.ndarray,
             dataset_file: str, tested: AdequacyChi2) -> PushRefusal | None:
    """Why the guard rails refuse the push (first reason that applies), or None.

    delta: (n,) rad corrections, zero where not pushed; pushed: (n,) bool; tested: what
    `adequacy_chi2` returned."""
    if not result.converged:
        return PushRefusal(f"the fit did not converge ({result.message}); not pushing "
                           "(--force to push anyway)", "not_converged",
                           resume_with("--force"))
    chi2_dof, band = tested.chi2_dof, chi2_dof_upper(tested.dof)
    if math.isfinite(chi2_dof) and math.isfinite(band) and chi2_dof > band:
        what = (" with the camera calibration's covariance" if tested.shared else
                "" if tested.kept is None else
                f" over the {tested.kept.n_kept} samples the {tested.kept.loss} loss keeps")
        return PushRefusal(
            f"the model does not explain the measurements (chi2/dof{what} "
            f"{chi2_dof:.3g} above its band {band:.3g}); run `hostpc diagnose "
            f"{dataset_file}` and rerun with the effect it names, or push anyway "
            "with --force", "model", ("diagnose", dataset_file))
    too_big = pushed & (np.abs(delta) > np.radians(limits))
    if np.any(too_big):
        return _limit_refusal(delta, too_big, labels, max_correction_deg, limits)
    return None


def _limit_refusal(delta: np.ndarray, too_big: np.ndarray, labels: tuple[str, ...],
                   max_correction_deg: float, limits: np.ndarray) -> PushRefusal:
    """The refusal of corrections beyond their push limits (`too_big`: (n,) bool), named
    by the largest. Its next command never sends the user back into it: every undeclared
    joint over the default limit by a swap's size is declared at once, with the joints
    declared already (`--swapped J1,J6`); a declared joint over its own limit gets a
    larger `--swap-limit`; else `--force`."""
    j = int(np.argmax(np.where(too_big, np.abs(delta), 0.0)))
    joint = labels[j] if labels[j] != f"q{j + 1}" else str(j + 1)  # head.q2, else 2
    declared = [k + 1 for k in range(delta.size) if limits[k] != max_correction_deg]
    over = [k + 1 for k in range(delta.size) if too_big[k] and labels[k] == f"q{k + 1}"
            and k + 1 not in declared
            and abs(math.degrees(delta[k])) > DEFAULT_MAX_CORRECTION_DEG]
    own = " of a declared swap (--swap-limit)" if j + 1 in declared else ""
    text = (f"joint {joint} correction {math.degrees(delta[j]):+.4f} deg exceeds the "
            f"limit{own} of {limits[j]:g} deg")
    if over:  # a declared swap raises its joints' limits only, where --force drops every rail
        joints = ",".join(f"J{k}" for k in sorted({*declared, *over}))
        others = [f"J{k + 1}" for k in range(delta.size) if too_big[k] and k + 1 != j + 1]
        text += ((f" (and {', '.join(others)} beyond theirs)" if others else "")
                 + f"; if their motors were swapped or re-mastered, declare them with "
                 f"--swapped {joints} (raises those joints' limits only); else check the cell "
                 "and the data, and rerun with --force to push anyway")
        return PushRefusal(text, "correction_limit", resume_with("--swapped", joints),
                           joint=j + 1, limit_deg=float(limits[j]), declare=over[0])
    own_over = [k for k in range(delta.size) if too_big[k] and k + 1 in declared]
    largest = max(abs(math.degrees(delta[k])) for k in own_over) if own_over else 0.0
    if own_over and largest < MAX_SWAP_LIMIT_DEG:
        wider = min(MAX_SWAP_LIMIT_DEG, float(max(2.0 * limits[j], math.ceil(1.5 * largest))))
        text += (f"; if the swap is that large, raise the declared swap's limit with "
                 f"--swap-limit {wider:g}; else check the cell and the data")
        return PushRefusal(text, "correction_limit", resume_with("--swap-limit", f"{wider:g}"),
                           joint=j + 1, limit_deg=float(limits[j]))
    text += "; check the cell and the data, and rerun with --force to push anyway"
    return PushRefusal(text, "correction_limit", resume_with("--force"), joint=j + 1,
                       limit_deg=float(limits[j]))


def _now() -> str:
    return _dt.datetime.now(_dt.UTC).isoformat(timespec="milliseconds")


class PushMismatch(ControllerError):
    """The controller's report of a push disagrees with what the host read before the
    write or asked of it: other previous offsets than the ones read (its report is
    inconsistent), or other offsets held after the write than the new ones (it clamped or
    ignored them). Exit 4, a controller that failed; the message names the joints, both
    values, what the controller holds now and the next command (`mismatch_line`);
    `record` is the push as recorded."""

    def __init__(self, message: str, record: PushRecord) -> None:
        super().__init__(message)
        self.record = record


async def execute_push(robot: RobotAdapter, plan: PushPlan, run_dir: Path, address: str,
                       journal: Journal | None = None) -> PushRecord:
    """Write plan.new to the controller, recording the intent durably first, and check what
    the controller then holds.

    Order: push.json (status "intent": previous and new offsets, time) and the journal's
    `push_intent` event, both fsync'ed; then the controller's write; then push.json again
    with the write's rollback id (still "intent") and the journal's `push_written` event,
    so that a read-back that fails leaves the id (`written_rollback_id`); then the
    controller's offsets read back (`get_offsets`, the same read plan.old came from); then
    push.json (status "pushed", rollback id) and the journal's `push` event. The previous offsets
    kept are plan.old, the ones read before the write, never the reply's `previous` (a
    rollback writes them back). A reply whose `previous` is not plan.old, or a read-back
    that is not plan.new (both to OFFSET_MATCH_TOLERANCE, the tolerance a resume
    recognises a push by), is recorded (PushRecord.reported_previous, .held) and raises
    PushMismatch. Raises InputError if the guard rail refused the plan (callers check
    `plan.refused`)."""
    if plan.refused:
        raise InputError(f"push refused: {plan.refused}")
    pushed = tuple(bool(v) for v in plan.pushed)
    intent = PushRecord(previous=plan.old.copy(), new=plan.new.copy(), rollback_id=None,
                        pushed=pushed, time=_now())
    write_json_atomic(run_dir / PUSH_FILE,
                      {"controller": address, "status": "intent", **intent.to_dict()})
    if journal is not None:
        journal.append(PushIntent(intent))
    reported_previous, rollback_id = await robot.set_offsets(plan.new)
    reported_previous = np.asarray(reported_previous, float)
    # the write was answered: its rollback id kept before the read-back, which may fail
    write_json_atomic(run_dir / PUSH_FILE,
                      {"controller": address, "status": "intent",
                       **dataclasses.replace(intent, rollback_id=str(rollback_id)).to_dict()})
    if journal is not None:
        journal.append(PushWritten(str(rollback_id), _now()))
    held = np.asarray(await robot.get_offsets(), float)
    record = PushRecord(
        previous=plan.old.copy(), new=plan.new.copy(), rollback_id=str(rollback_id),
        pushed=pushed, time=_now(), held=None if same_offsets(held, plan.new) else held,
        reported_previous=(None if same_offsets(reported_previous, plan.old)
                           else reported_previous))
    write_json_atomic(run_dir / PUSH_FILE,
                      {"controller": address, "status": "pushed", **record.to_dict()})
    if journal is not None:
        journal.append(Pushed(record))
    if record.inconsistent:
        raise PushMismatch(mismatch_line(record, address, run_dir, plan.display_names()),
                           record)
    return record


def _deg(value: float) -> str:
    return f"{math.degrees(value):+.5f}"


def _differences(names: list[str], shown: np.ndarray, expected: np.ndarray,
                 what: str) -> str:
    """`J2 +0.05730 deg (pushed +0.81930)`, per joint where shown and expected (n,) rad
    differ; a count when their lengths do."""
    if shown.shape != expected.shape:
        return f"{shown.size} offsets for {expected.size} joints"
    return ", ".join(f"{names[j]} {_deg(shown[j])} deg ({what} {_deg(expected[j])})"
                     for j in range(expected.size)
                     if not same_offsets(shown[j:j + 1], expected[j:j + 1]))


def mismatch_line(record: PushRecord, address: str, run_dir: Path,
                  names: list[str] | None = None) -> str:
    """The one line of a push the controller reported inconsistently (PushMismatch):
    which joints, its values and the host's (degrees), what it holds now, the next
    command. names: how the joints are called (default J1..Jn)."""
    names = names or [f"J{j + 1}" for j in range(record.new.size)]
    if record.held is None:
        head = (f"push not trusted: the controller at {address} holds the pushed offsets, "
                "but its report is inconsistent")
        now = record.new
    else:
        head = (f"push failed: the controller at {address} did not store the pushed zero "
                "offsets (read back after its reply): "
                + _differences(names, record.held, record.new, "pushed"))
        now = record.held
    if record.reported_previous is not None:
        head += ("; its reply names as the offsets it replaced "
                 + _differences(names, record.reported_previous, record.previous,
                                "read before the write:"))
    holds = ", ".join(f"{names[j] if j < len(names) else f'J{j + 1}'} {_deg(v)}"
                      for j, v in enumerate(now))
    line = f"{head}; it holds now [deg]: {holds}"
    if (record.held is not None and record.reported_previous is None
            and same_offsets(record.held, record.previous)):
        return (f"{line} (its previous offsets: the write changed nothing); see what it "
                f"holds with: hostpc status --robot {address}")
    return (f"{line}; {run_dir}/{PUSH_FILE} keeps the offsets read before the push: restore "
            f"them with: hostpc rollback --run {run_dir} (see what it holds with: hostpc "
            f"status --robot {address})")


def written_rollback_id(journal: Journal) -> str | None:
    """The rollback id of a write the controller answered whose read-back never came (the
    journal's last push event is `push_written`), else None."""
    last = journal.last_event(PushIntent, PushWritten, Pushed)
    return last.rollback_id if isinstance(last, PushWritten) else None


def read_back_lost_line(rollback_id: str, run_dir: Path, address: str) -> str:
    """What a push whose write the controller answered (`rollback_id`) but whose read-back
    never came leaves: offsets nobody checked; the next commands."""
    return (f"the controller at {address} took the write (rollback id {rollback_id}) but "
            "reading its offsets back failed: it holds the new offsets or others, NOT "
            f"checked ({run_dir}/{PUSH_FILE} keeps the previous ones and the rollback id); "
            f"see which with: hostpc status --robot {address}; restore the previous ones "
            f"with: hostpc rollback --run {run_dir}")


def cut_short_line(exc: Exception, run_dir: Path, address: str,
                   rollback_id: str | None = None) -> str:
    """The line of a push whose answer never came (`exc`: link lost, no reply, a reply
    that broke the protocol): the controller may hold either offsets; the next commands.
    rollback_id: the write's (`written_rollback_id`), when it was answered and only the
    read-back failed."""
    if rollback_id is not None:
        return f"{exc}; {read_back_lost_line(rollback_id, run_dir, address)}"
    return (f"{exc}; the push was cut short: the controller at {address} may hold the new "
            f"offsets or the previous ones ({run_dir}/{PUSH_FILE} keeps both); see which with: "
            f"hostpc status --robot {address}; restore the previous ones either way with: "
            f"hostpc rollback --run {run_dir}")


def same_offsets(a: Any, b: Any) -> bool:
    """True if two offset vectors (n,) rad agree to OFFSET_MATCH_TOLERANCE."""
    a = np.asarray(a, float)
    b = np.asarray(b, float)
    return a.shape == b.shape and bool(np.allclose(a, b, rtol=0.0, atol=OFFSET_MATCH_TOLERANCE))


def intent_outcome(intent: PushRecord, offsets_now: np.ndarray) -> str | None:
    """Did a push whose result was never recorded reach the controller? From the offsets
    the controller reports now (n,) rad: "pushed" (they are the intended new ones),
    "not_pushed" (still the previous ones) or None (neither: changed by someone else)."""
    if same_offsets(offsets_now, intent.new):
        return "pushed"
    if same_offsets(offsets_now, intent.previous):
        return "not_pushed"
    return None


async def rollback_run(robot: RobotAdapter, record: PushRecord,
                       offsets_now: np.ndarray) -> tuple[np.ndarray, str]:
    """Undo the push recorded in a run's push.json (hostpc.calibrate.push_file, validated),
    the controller's offsets being `offsets_now` (n,) rad.

    With a rollback id: `rollback` (falling back to writing the previous offsets). Without
    one (the run stopped between writing its intent and recording the result, or the push
    was recovered on resume): the controller's offsets decide; the intended new ones ->
    the previous ones are written ("previous_offsets_written"); still the previous ones ->
    nothing to do ("not_pushed"). Anything else is an InputError (someone else changed
    them). Returns (offsets now (n,) rad, how)."""
    previous = record.previous
    if record.rollback_id is not None:
        return await rollback(robot, record.rollback_id, previous)
    outcome = intent_outcome(record, offsets_now)
    if outcome == "not_pushed":
        return offsets_now, "not_pushed"
    if outcome is None:
        raise InputError("the controller's zero offsets are neither the ones the run meant "
                         "to write nor the ones it found; not writing anything")
    await robot.set_offsets(previous)
    return np.asarray(await robot.get_offsets(), float), "previous_offsets_written"


async def rollback(robot: RobotAdapter, rollback_id: str,
                   previous: np.ndarray | None = None) -> tuple[np.ndarray, str]:
    """Restore the offsets replaced by the write `rollback_id`.

    With `previous` (n,) rad, the offsets the host read before that write: if the
    controller no longer knows the id (it restarted), or its rollback leaves other offsets
    than those (it replaced others than it was read to hold, or does not undo), the
    previous offsets are written directly ("previous_offsets_written"). Returns (offsets
    now (n,), how)."""
    from hostpc.transport import ControllerRefusedError

    try:
        now = np.asarray(await robot.rollback(rollback_id), float)
        if previous is None or same_offsets(now, previous):
            return now, "rollback_id"
    except ControllerRefusedError as exc:
        if exc.code != "unknown_rollback" or previous is None:
            raise
    await robot.set_offsets(np.asarray(previous, float))
    return np.asarray(await robot.get_offsets(), float), "previous_offsets_written"


def export_offsets(robot: RobotAdapter, run_dir: Path, robot_name: str, plan: PushPlan,
                   status: str, progress: Any) -> dict[str, str] | None:
    """For a robot that keeps no zero offsets (an adapter whose capabilities include an
    `OffsetExport`, the UR driver) write the compensated offsets as files into the run
    folder: the only lasting form of its push. None if the adapter writes the controller or
    nothing is pushed."""
    export = robot.capabilities.offset_export
    if (export is None or status not in ("pushed", "disabled") or plan.refused
            or not plan.anything):
        return None
    paths = export.export_offsets(run_dir, robot_name, plan.new)
    progress.message("offsets exported for the robot's own software: "
                     + ", ".join(str(path) for path in paths.values()))
    return {kind: str(path) for kind, path in paths.items()}
