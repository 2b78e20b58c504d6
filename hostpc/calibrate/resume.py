"""A resumed calibration run: what its journal says about settings, offsets, push and clock.

A run folder that holds a journal is resumed (`hostpc calibrate --resume`). Before anything
moves the runner checks that the controller still has the run's offsets (or the ones the
run pushed, or meant to push), settles a push cut short (``push_intent`` without its
result) from the controller's offsets, takes the robot to be where the controller reads
it (`resume_pose`: a robot moved since its last journaled pose is never taken to be
there), and keeps the samples' time ``t`` from going backwards when the controller's (or
the host's) clock restarted. All of it reads and
appends to the run's `Journal`; nothing here talks to the robot.
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from hostpc.calibrate.journal import Journal, sample_times, shift_sample_t
from hostpc.calibrate.journal_events import (
    Note,
    Pushed,
    PushIntent,
    Rollback,
    RunFinished,
    Verified,
    VerifyStart,
)
from hostpc.calibrate.push import (
    PUSH_FILE,
    PushMismatch,
    intent_outcome,
    mismatch_line,
    same_offsets,
    written_rollback_id,
)
from hostpc.calibrate.refusals import stopped
from hostpc.calibrate.run_result import RunResult
from hostpc.errors import ControllerError, InputError
from hostpc.files import write_json_atomic
from hostpc.methods.base import Progress, RunSettings, SampleRecord
from hostpc.robots.base import RobotState

RESUME_OVERRIDABLE = frozenset({"push", "force", "max_correction_deg", "verify_factor",
                                "verify_alpha", "verify_tolerance_mm", "effects", "plugins",
                                "require_joints", "swapped", "swap_limit_deg"})
"""Settings a resume may change (they act after the measurements: a new model refits the
measured dataset, then pushes and verifies)."""
CLOCK_TOLERANCE_S = 1e-6
AT_POSE_RAD = 1e-4
"""A controller reading this close (every joint, rad) to the journaled pose is that pose."""


@dataclass(frozen=True)
class ResumeOverrides:
    """What a resume's command line gives (None: not given): the ``RESUME_OVERRIDABLE``
    settings, and the model's known frames and cell reference (read by the runner)."""

    push: bool | None = None
    force: bool | None = None
    max_correction_deg: float | None = None
    verify_factor: float | None = None
    verify_alpha: float | None = None
    verify_tolerance_mm: float | None = None
    effects: str | None = None
    plugins: tuple[str, ...] | None = None
    require_joints: str | None = None
    swapped: tuple[int, ...] | None = None
    swap_limit_deg: float | None = None
    known: str | None = None
    reference: str | None = None
    separate: tuple[str, str] | None = None  # --separate A,B (hostpc.calibrate.separate)

    def items(self) -> list[tuple[str, Any]]:
        """(name, value) of every option, in order."""
        return [(f.name, getattr(self, f.name)) for f in dataclasses.fields(self)]

    @property
    def asked(self) -> bool:
        """True if the resume asks for anything beyond finishing the run (an option that
        acts after the measurements: push, force, limits, verification, model)."""
        return any(value not in (None, False, [], ()) for _, value in self.items())

    @property
    def push_asked(self) -> bool:
        """True if the resume asks for the push (--push or --force)."""
        return self.push is True or self.force is True

    @property
    def remodel(self) -> bool:
        """True if the resume changes the model (effects, plugins, known frames, reference)."""
        return any((self.effects, self.plugins, self.known, self.reference))


def resume_settings(settings: RunSettings, overrides: ResumeOverrides, journal: Journal,
                    progress: Progress) -> RunSettings:
    """The run's settings with this resume's `overrides` applied (only the
    ``RESUME_OVERRIDABLE`` ones that are given and differ); a change is journaled, and
    the runner writes the changed settings into run.json (`persisted`), so a later resume
    keeps them (--swapped, --swap-limit, --max-correction, ... ; --known is kept in its
    cell). --force is one push's decision: never kept, so only a resume that gives it
    forces. A --separate resume measures and tests, and pushes only with its own --push.
    --swapped adds to the run's declared swaps (their union: a joint declared swapped
    anywhere in the run's history stays declared; a note says so when fewer are named).
    The same `settings` object when nothing changed."""
    asked = dict(overrides.items())
    if asked.get("swapped") is not None:  # a resume adds swapped joints, never un-declares
        kept = sorted(set(settings.swapped) - set(asked["swapped"]))
        asked["swapped"] = tuple(sorted(set(settings.swapped) | set(asked["swapped"])))
        if kept:
            text = (f"note: {', '.join(f'J{j}' for j in kept)} "
                    f"{'stays' if len(kept) == 1 else 'stay'} declared swapped (an "
                    "earlier --swapped of this run): a resume adds swapped joints, it cannot "
                    "un-declare one")
            journal.append(Note(text))
            progress.message(text)
    changed = {k: v for k, v in asked.items()
               if k in RESUME_OVERRIDABLE and v is not None
               and getattr(settings, k) != v}
    if settings.force and not overrides.force:
        changed["force"] = False  # an earlier session's --force does not carry over
    if overrides.separate and settings.push and overrides.push is not True \
            and not overrides.force:
        changed["push"] = False  # this session only: the runner does not persist it
    if changed:
        settings = dataclasses.replace(settings, **changed)
        journal.append(Note("settings changed on resume", overrides=changed))
        progress.message("resume with " + ", ".join(
            f"{k}={v}" for k, v in changed.items()))
    return settings


def persisted(settings: RunSettings, stored: RunSettings,
              overrides: ResumeOverrides) -> RunSettings:
    """What run.json keeps of a resume's `settings` (`stored`: what it held): never
    --force, and not the push a --separate resume left out."""
    kept = dataclasses.replace(settings, force=False)
    if overrides.separate and overrides.push is None:
        kept = dataclasses.replace(kept, push=stored.push)
    return kept


def check_resume_offsets(journal: Journal, run_dir: Path, initial: np.ndarray,
                         now: np.ndarray, address: str) -> None:
    """A resume continues only if the controller's offsets are the run's initial ones,
    the ones it pushed, or the ones a push cut short meant to write. Offsets that are the
    ones a controller held after a push it did not store as asked (PushRecord.held) raise
    PushMismatch again (its line and next command: hostpc rollback --run DIR)."""
    pushes = journal.events(Pushed)
    if same_offsets(now, initial):
        return
    if pushes and same_offsets(now, pushes[-1].record.new):
        return
    held = pushes[-1].record.held if pushes else None
    if held is not None and same_offsets(now, held):
        raise PushMismatch(mismatch_line(pushes[-1].record, address, run_dir),
                           pushes[-1].record)
    last = journal.last_event(PushIntent, Pushed)
    if isinstance(last, PushIntent) and same_offsets(now, last.record.new):
        return
    raise InputError(
        f"the controller's zero offsets changed since the run in {run_dir} started "
        f"(now {_deg_list(now)} deg, then {_deg_list(initial)} deg); the journaled "
        "samples cannot be combined with new ones: start a new run")


def resume_pose(journal: Journal, reading: Sequence[float] | np.ndarray,
                offsets_now: np.ndarray, initial: np.ndarray,
                progress: Progress) -> np.ndarray:
    """Where a resumed run's robot is, in the frame of its last journaled pose: that pose
    (``Journal.last_end``) when the controller reads it, else the reading. A moved robot
    (jogged, a move the journal does not hold such as the coarse swap search, a restarted
    simulator at its start pose) is never taken to be where the journal left it: the
    first moves are checked from where it is.

    The controller reports ``encoder + offset``, so the reading under the offsets it holds
    now (`offsets_now`) is converted, here and only here, to the offsets the last pose was
    measured under: a fit pose under the run's `initial` ones, a verification pose under
    the last pushed ones. Nothing journaled: the reading as it is."""
    q_read = np.asarray(reading, float)
    last = journal.last_end()
    if last is None:
        return q_read
    phase, q_end = last
    pushes = journal.events(Pushed)
    held = (np.asarray(initial, float) if phase == "fit" or not pushes
            else np.asarray(pushes[-1].record.new, float))
    q_read = q_read - (np.asarray(offsets_now, float) - held)
    journaled = np.asarray(q_end, float)
    if journaled.shape != q_read.shape:
        return q_read
    moved = float(np.max(np.abs(q_read - journaled))) if q_read.size else 0.0
    if moved <= AT_POSE_RAD:
        return journaled
    progress.message(f"the robot is not where the journal left it (a joint "
                     f"{math.degrees(moved):.3f} deg away): going on from where the "
                     "controller reads it")
    return q_read


class SampleClock:
    """Keeps sample `t` continuing across a resume.

    last_t: the last journaled sample's t (s), None for a new run; t_shift: added to new
    samples' t (s), set by the first new sample of a resume.
    """

    def __init__(self, journal: Journal, progress: Progress) -> None:
        self.journal = journal
        self.progress = progress
        self.last_t: float | None = None
        self.t_shift: float | None = None

    def time_origin(self, started: float | None, state: RobotState) -> float:
        """The controller time (s) sample `t` counts from: the run's start (`started`, the
        controller time in the run header, None if not known); on a resume
        whose controller clock went back (a restarted controller, e.g. a resumed `--robot
        sim` run) moved so that the new samples' t continue from the last journaled one."""
        t0 = float(started or 0.0)
        now = state.controller_time
        if self.last_t is None or now is None:
            return t0
        if now < t0 + self.last_t - CLOCK_TOLERANCE_S:
            origin = now - self.last_t
            self.journal.append(Note("controller clock restarted: new samples' t "
                                     "continue from the last journaled one",
                                     last_t=self.last_t, time_origin=origin))
            self.progress.message(f"the controller's clock restarted: sample t continues "
                                  f"from {self.last_t:.1f} s")
            return origin
        return t0

    def continue_t(self, record: SampleRecord) -> SampleRecord:
        """On a resume, keep `t` from going backwards for any method (e.g. one that times
        samples with the host's clock): the first new sample sets the shift."""
        times = sample_times(record.sample)
        if self.last_t is None or not times or record.sample is None:
            return record
        if self.t_shift is None:
            self.t_shift = max(0.0, self.last_t - min(times))
            if self.t_shift > 0.0:
                self.journal.append(Note("sample t went backwards on resume; new "
                                         "samples' t shifted", t_shift=self.t_shift))
        if self.t_shift == 0.0:
            return record
        return dataclasses.replace(record, sample=shift_sample_t(record.sample,
                                                                  self.t_shift))


def settle_push_intent(journal: Journal, run_dir: Path, address: str, progress: Progress,
                       offsets_now: np.ndarray) -> None:
    """A `push_intent` without its result (the run stopped while writing the offsets):
    the controller's offsets say whether the write happened. Written: journal it as the
    push (with the write's rollback id if the controller answered it and only the
    read-back was lost, `push_written`; else none, and `hostpc rollback --run` writes the
    previous offsets). Not written: note it and drop the intent's push.json."""
    last = journal.last_event(PushIntent, Pushed)
    if not isinstance(last, PushIntent):
        return
    latest = journal.last_event("push_intent", "push", "push_refused")
    if latest is not None and latest.get("event") == "push_refused":
        return  # the controller refused the write (its own limit): nothing was cut short
    written = written_rollback_id(journal)  # the write answered, its read-back lost
    record = dataclasses.replace(last.record, rollback_id=written)
    outcome = intent_outcome(record, offsets_now)
    if outcome == "pushed":
        journal.append(Pushed(record, recovered=True))
        write_json_atomic(run_dir / PUSH_FILE,
                          {"controller": address, "status": "pushed",
                           **record.to_dict(), "recovered": True})
        progress.message("the push cut short in the last session reached the "
                         "controller (it has the intended offsets): recorded as "
                         "pushed, " + ("without a rollback id" if written is None
                                       else f"rollback id {written}"))
    elif outcome == "not_pushed":
        journal.append(Note("the push cut short in the last session did not reach the "
                            "controller"))
        (run_dir / PUSH_FILE).unlink(missing_ok=True)
        progress.message("the push cut short in the last session did not reach the "
                         "controller (it has the previous offsets)")


class PushLost(ControllerError):
    """The controller no longer has the offsets this run pushed (it has its previous ones
    again, and no rollback was journaled: it restarted, or someone wrote them)."""


class VerifyLost(ControllerError):
    """Every verification pose of this round was skipped: no verdict (resumable)."""


def verify_lost_line(lost: Sequence[SampleRecord], n_verify: int, pushed: bool,
                     run_dir: Path) -> str:
    """The one line of a lost verification round (`lost`: its skipped records) and its
    next command. Only moves stopped on the way (an abort storm) are worth measuring again
    (a resume); a pose lost to what the robot found there (no contact, out of view) is lost
    again by a resume: with offsets pushed, the next command restores the previous ones;
    with nothing pushed, it diagnoses the fit's data."""
    reasons = sorted({str(r.reason) for r in lost})
    state = "the pushed offsets stay in the controller" if pushed else "nothing was pushed"
    line = (f"verification lost: all {n_verify} verification poses were skipped "
            f"({'; '.join(reasons)}); {state}")
    if lost and all(stopped(r) for r in lost):
        return f"{line}; measure them again with: hostpc calibrate --resume {run_dir}"
    if pushed:
        return (f"{line}; measured again they would be lost again (the robot does not reach "
                "what the fitted offsets predict): restore the previous offsets with: "
                f"hostpc rollback --run {run_dir}")
    return (f"{line}; measured again they would be lost again (the robot does not reach "
            "what the fit predicts): look at the fit's data with: hostpc diagnose "
            f"{run_dir}/dataset.json")


def push_state(journal: Journal, run_dir: Path, progress: Progress, offsets_now: np.ndarray,
               push_asked: bool, zero: np.ndarray) -> tuple[str, np.ndarray] | None:
    """The status of the push this run already journaled, from the controller's offsets.

    ("pushed", the delta in the controller) if it has the pushed offsets; ("rolled_back",
    `zero`) if it has the previous ones and `hostpc rollback --run` journaled a rollback
    since; PushLost if it has the previous ones without a journaled rollback; None if there
    is no journaled push, or the resume asks for the push again (`push_asked`)."""
    pushes = journal.events(Pushed)
    if not pushes:
        return None
    new, previous = pushes[-1].record.new, pushes[-1].record.previous
    if same_offsets(offsets_now, new):
        verified = any(same_offsets(e.offsets, new) for e in journal.events(Verified))
        progress.message("resume after the push: the controller has the pushed offsets; "
                         + ("already verified" if verified
                            else "not verified yet: verifying now on fresh poses"))
        return "pushed", new - previous
    if push_asked:
        return None
    last = journal.last_event(Pushed, Rollback)
    if isinstance(last, Rollback):
        progress.message(
            f"the push journaled in {run_dir} was rolled back ({last.time or ''}, the "
            "controller has its previous offsets again): not pushing again; resume with "
            "--push (or --force) to push again")
        return "rolled_back", zero
    raise PushLost(
        "push lost: the controller no longer has the offsets this run pushed (it has the "
        "previous ones again and no rollback was journaled: it restarted, or someone wrote "
        f"them); push again with: hostpc calibrate --resume {run_dir} --push")


def verify_round(journal: Journal, offsets: np.ndarray, pushed_delta: np.ndarray,
                 n_verify: int) -> tuple[int, int]:
    """(round, first sample index) of the verification to measure now.

    The verification poses are measured in rounds, each under one set of controller
    offsets (journal event `verify_start`); sample indices of round r are r*K .. r*K+K-1
    (K = n_verify, pose i % K). The last round continues if it was measured under these
    offsets and pushed delta, started after the journal's latest push (a push again of the
    same offsets, e.g. after a restarted controller lost them, starts a new round) and is
    not lost (every pose skipped); else a new round starts, so a verdict only ever uses
    poses measured after the push it judges."""
    rounds = journal.events(VerifyStart)
    if rounds and journal.last_position(VerifyStart) > journal.last_position(Pushed):
        last = rounds[-1]
        first = last.first
        records = [r for r in journal.records("verify") if first <= r.index < first + n_verify]
        lost = len(records) == n_verify and not any(r.ok for r in records)
        if (same_offsets(last.offsets, offsets)
                and same_offsets(last.pushed_delta, pushed_delta) and not lost):
            return last.round, first
    used = [r.index for r in journal.records("verify")]
    number = len(rounds) if not used else max(len(rounds), max(used) // n_verify + 1)
    journal.append(VerifyStart(round=number, first=number * n_verify,
                               offsets=tuple(float(v) for v in offsets),
                               pushed_delta=tuple(float(v) for v in pushed_delta)))
    return number, number * n_verify


def stored_result(journal: Journal, run_dir: Path, offsets_now: np.ndarray, asked: bool,
                  progress: Progress) -> RunResult | None:
    """The finished run's result if this resume has nothing to do: the run wrote
    its result (journal event `result`) under the offsets the controller has now, and the
    resume asks for nothing new (`asked`: --push, --force, --effects, ...) or the stored
    result is pushed offsets that PASSed their verification (never overwritten). A PASS of
    a run that pushed nothing (refused, --no-push) is only a model check on a few fresh
    poses: a resume that asks for something (the README's `--effects +joint_compliance
    --push` after a refused push) continues. None: continue the run."""
    final = journal.last(RunFinished)
    path = run_dir / "result.json"
    if final is None or not path.is_file() or not same_offsets(final.offsets, offsets_now):
        return None
    if asked and not (final.verdict == "PASS" and final.push == "pushed"):
        return None
    try:
        stored = RunResult.from_dict(json.loads(path.read_text(encoding="utf-8")))
    except (OSError, ValueError, KeyError, TypeError):
        return None
    status = stored.push.status
    verdict = final.verdict
    if status == "pushed" and verdict is not None:
        what = f"already pushed and verified ({verdict})"
    else:
        what = f"already finished (push: {status}, verification: {verdict or 'none'})"
    note = ("; verified pushed offsets are never overwritten: start a new run to change "
            "them" if asked else "")
    progress.message(f"{what}: the stored result follows; nothing changed{note}")
    return stored


def archive_result(run_dir: Path) -> None:
    """Before a resume writes a new result: keep the old result.json / summary.txt as
    result.N.json / summary.N.txt (N = 1, 2, ...), so no verdict is ever overwritten."""
    old = run_dir / "result.json"
    if not old.is_file():
        return
    number = 1
    while (run_dir / f"result.{number}.json").exists():
        number += 1
    old.rename(run_dir / f"result.{number}.json")
    summary = run_dir / "summary.txt"
    if summary.is_file():
        summary.rename(run_dir / f"summary.{number}.txt")


def _deg_list(values: np.ndarray) -> str:
    return "[" + ", ".join(f"{math.degrees(v):+.4f}" for v in values) + "]"
