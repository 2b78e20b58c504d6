"""What a calibration run did to the ROBOT: one verdict, per joint, from the journal alone.

`RobotOutcome` is the one source of truth every view reads (result.json's "outcome" block,
summary.txt, report.html, the archive, the station's registers). It is derived ONLY from
the run's journal (what was pushed, verified, rolled back, refused) and the fit's per-joint
sources (joint_status.py, stored in the outcome's "joints" so a later rollback or resume
re-derives it without refitting). Nothing else decides a verdict; a model check (a
verification with nothing pushed) is never one.

Verdicts (the first that applies, top down):

    ERROR           the run did not finish (no `result` event); the controller text says
                    what it holds (e.g. new offsets, NOT verified: resume it)
    FAIL            offsets pushed, and their verification failed                  (exit 6)
    ROLLED_BACK     the push was undone by `hostpc rollback --run`                 (exit 0)
    REFUSED         a guard rail refused the push: offsets unchanged               (exit 5)
    JOINTS_MISSING  a required joint (`--require-joints`) is not calibrated from data
                    (the calibrated joints are still pushed and verified)           (exit 7)
    PASS            offsets pushed and verified
    NOT_VERIFIED    offsets pushed, no verification measured (`--verify-poses 0`)  (exit 0)
    NOT_PUSHED      --no-push, nothing to push (a model check at most)             (exit 0)

A robot that keeps no zero offsets (a UR, `--driver ur`: the driver table's `host_offsets`)
takes a "push" in the driver on the host, for that session only: its outcome is not
`pushed` but `applied_on_host`, its controller text says the controller's zeros are
unchanged and how to keep the offsets (the exported files), and each joint's row says so;
the verdict (PASS: verified through the host's offsets) is as for a push.

A refusal counts while no push of the run is in the controller (a refused re-push on a
resume leaves the earlier, verified push standing).

A joint is "calibrated" when the data determine it (source "data") and, if it was pushed,
its verification did not fail; a hold or prior value never is (joint_status.py); after a
rollback no joint is (its zero is the one before the run again: ROLLED_BACK is no pass). A joint
only a cell reference's frames identify (J1, J6 with every frame estimated) is restored TO
THE REFERENCE: its `zero_from` names the reference's recording run and whether that run
calibrated it ("measured") or not ("as_found": its zero as at that run, not measured
against a surveyed frame; "unknown": a reference written before zerocal recorded it). The
headline and the joint's row say so unless it was "measured".
"""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from hostpc.calibrate.joint_status import JointSource
from hostpc.calibrate.next_commands import resume_command, rollback_command, with_archive
from hostpc.calibrate.reference import CellReference
from hostpc.calibrate.refusals import PushRefusal
from hostpc.calibrate.summary import (
    EXIT_JOINTS_NOT_CALIBRATED,
    EXIT_PUSH_REFUSED,
    EXIT_VERIFY_FAILED,
)
from hostpc.json_object import JsonObject
from hostpc.model.joint_offsets import offset_name

VERDICTS = ("PASS", "FAIL", "REFUSED", "NOT_PUSHED", "NOT_VERIFIED", "ROLLED_BACK",
            "JOINTS_MISSING", "ERROR")
EXIT_CODES = {"PASS": 0, "NOT_PUSHED": 0, "NOT_VERIFIED": 0, "ROLLED_BACK": 0,
              "REFUSED": EXIT_PUSH_REFUSED, "FAIL": EXIT_VERIFY_FAILED,
              "JOINTS_MISSING": EXIT_JOINTS_NOT_CALIBRATED, "ERROR": 1}
"""`hostpc calibrate`'s exit code per verdict (ERROR: the error's own code at the CLI)."""
_LEGACY_SWAP_HINT = re.compile(r"declare it with --swapped (J\d+)")
"""The push guard's words for a correction beyond the default limit, read only from a
journal whose `push_refused` event has no structured next command (written before it)."""
JOURNAL_KINDS = ("push_intent", "push", "verify", "rollback", "push_refused", "resumed",
                 "result")
"""The journal events an outcome reads (Journal.timeline)."""
_KNOWN_FIX = re.compile(r"--known (\S+)")
"""The frames a joint's fix names (joint_status: `--known target (or a cell reference...)`)."""
_MATCH = 1e-9  # rad: the verified offsets are the pushed ones


@dataclass(frozen=True)
class JointOutcome:
    """One joint after the run: status calibrated | not_calibrated; source data | hold |
    prior | none; pushed: its new offset is in the controller now; verified: that offset
    passed (True) / failed (False) verification, None if not pushed or not verified."""

    joint: int
    label: str
    status: str
    source: str
    pushed: bool
    verified: bool | None
    reason: str | None
    fix: str | None
    restored_from: str | None = None
    """The recording run of the cell reference this joint is restored to (JointSource)."""
    reference_zero: str | None = None
    """"measured" | "as_found" | "unknown" with `restored_from` (JointSource)."""
    applied_on_host: bool = False
    """Its new offset is applied in the driver on the host for the session only (a robot
    that keeps no zero offsets): not pushed, the controller's zero is unchanged."""

    @property
    def calibrated(self) -> bool:
        """Calibrated from the data (and, if pushed, not failed in verification)."""
        return self.status == "calibrated"

    @property
    def as_found(self) -> bool:
        """Calibrated only through a cell reference whose recording run did not calibrate
        it (or may not have: "unknown"): its zero is the one it had then."""
        return self.calibrated and self.restored_from is not None and \
            self.reference_zero != "measured"

    def zero_from(self) -> JsonObject | str | None:
        """result.json's record of where the value came from: "measurements", the cell
        reference ({"reference_run", "reference_zero"}), or None (not from the data)."""
        if self.source != "data":
            return None
        if self.restored_from is None:
            return "measurements"
        return {"reference_run": self.restored_from, "reference_zero": self.reference_zero}

    @property
    def on_robot(self) -> bool:
        """Calibrated from data and, if pushed, verified (station register 14)."""
        return self.calibrated and (not self.pushed or self.verified is True)

    def to_dict(self) -> JsonObject:
        return {"joint": self.joint, "label": self.label, "status": self.status,
                "source": self.source, "pushed": self.pushed, "verified": self.verified,
                "reason": self.reason, "fix": self.fix, "zero_from": self.zero_from(),
                "applied_on_host": self.applied_on_host}

    @classmethod
    def from_dict(cls, row: Mapping[str, Any]) -> JointOutcome:
        """A joint row as stored (result.json's outcome block, `to_dict`), for readers of
        stored runs (the archive, the station's registers) to ask the same properties;
        absent keys (an older result) take their defaults. KeyError without "joint"."""
        joint = int(row["joint"])
        zero = row.get("zero_from")
        restored = zero if isinstance(zero, Mapping) else None
        verified = row.get("verified")
        return cls(
            joint=joint, label=str(row.get("label") or f"q{joint}"),
            status=str(row.get("status") or "not_calibrated"),
            source=str(row.get("source") or "none"), pushed=row.get("pushed") is True,
            verified=verified if isinstance(verified, bool) else None,
            reason=row.get("reason"), fix=row.get("fix"),
            restored_from=(None if restored is None
                           else str(restored.get("reference_run") or "")),
            reference_zero=None if restored is None else restored.get("reference_zero"),
            applied_on_host=row.get("applied_on_host") is True)


@dataclass(frozen=True)
class OutcomeEvent:
    """Something that happened to the controller: pushed | verified | model_check |
    rolled_back | refused | resumed, at an ISO time (None in journals that lack it)."""

    at: str | None
    event: str
    details: tuple[tuple[str, Any], ...] = ()

    def to_dict(self) -> JsonObject:
        return {"at": self.at, "event": self.event, **dict(self.details)}


@dataclass(frozen=True)
class RobotOutcome:
    """The run's outcome (module docstring); `to_dict` is result.json's "outcome" block."""

    verdict: str
    controller: str
    pushed: bool
    verified: bool | None
    rolled_back_at: str | None
    joints: tuple[JointOutcome, ...]
    required_joints: tuple[int, ...]
    missing_required: tuple[int, ...]
    headline: str
    next_command: str | None
    events: tuple[OutcomeEvent, ...] = field(default=())
    refused_reason: str | None = None
    refusal: PushRefusal | None = None
    """The refusal's structured form (which guard, the next command), None when the
    journal predates it."""
    unknown_zeros: tuple[int, ...] = ()
    """The joints declared swapped that the run did not calibrate (`unknown_swapped_zeros`),
    known when the next command was written: it never proposes a reference from this run
    then (result.json `unknown_zeros`; a result without the key predates the rule)."""
    applied_on_host: bool = False
    """The new offsets are applied on the host for the session only (module docstring):
    `pushed` is False, the controller's zeros are unchanged."""
    archive: str | None = None
    """The results archive the run is archived in (run.json `archive`, without a
    password): every command that acts on the run again names it (next_commands.py)."""

    @property
    def exit_code(self) -> int:
        return EXIT_CODES[self.verdict]

    def to_dict(self) -> JsonObject:
        return {"verdict": self.verdict, "controller": self.controller, "pushed": self.pushed,
                "verified": self.verified, "rolled_back_at": self.rolled_back_at,
                "joints": [j.to_dict() for j in self.joints],
                "required_joints": list(self.required_joints),
                "missing_required": list(self.missing_required),
                "headline": self.headline, "next_command": self.next_command,
                "events": [e.to_dict() for e in self.events],
                "refused_reason": self.refused_reason, "exit_code": self.exit_code,
                "unknown_zeros": list(self.unknown_zeros),
                "applied_on_host": self.applied_on_host, "archive": self.archive}


def parse_required_joints(text: str | None, n_joints: int | None = None) -> tuple[int, ...]:
    """`--require-joints`: "all" (every joint), "none" or None (no requirement), or a
    comma list of 1-based joint numbers ("1,2,6"). n_joints None: syntax only; "all"
    then gives (). ValueError naming the bad item."""
    if text is None or text.strip().lower() in ("", "none"):
        return ()
    if text.strip().lower() == "all":
        return tuple(range(1, (n_joints or 0) + 1))
    joints: list[int] = []
    for item in text.split(","):
        item = item.strip()
        if not item.isdigit() or int(item) < 1:
            raise ValueError(f"--require-joints {text}: {item!r} is not a joint number "
                             "(all, none, or e.g. 1,2,6)")
        if n_joints is not None and int(item) > n_joints:
            raise ValueError(f"--require-joints {text}: joint {item} does not exist (the "
                             f"robot has {n_joints} joints)")
        if int(item) not in joints:
            joints.append(int(item))
    return tuple(sorted(joints))


def sources_from_outcome(block: JsonObject) -> tuple[JointSource, ...]:
    """The fit's per-joint sources as a stored outcome block holds them (for a rollback or
    a later view to derive the outcome again without the fit)."""
    rows = [JointOutcome.from_dict(row) for row in block.get("joints", [])
            if isinstance(row, Mapping)]
    return tuple(JointSource(j.joint, j.label, j.source, j.reason, j.fix, j.restored_from,
                             j.reference_zero) for j in rows)


def restored_to_reference(sources: Sequence[JointSource], coverage: Mapping[str, Any] | None,
                          reference: CellReference | None) -> tuple[JointSource, ...]:
    """The fit's sources with the joints only the reference's frames identify (the plan's
    joint coverage, `resolved_by_reference`) marked as restored to that reference, with
    its record of their zeros (CellReference.zero_of)."""
    resolved = set((coverage or {}).get("resolved_by_reference") or ())
    if reference is None or not resolved:
        return tuple(sources)
    run = reference.source_run or f"the reference of {reference.date}"
    return tuple(dataclasses.replace(s, restored_from=run,
                                     reference_zero=reference.zero_of(s.joint))
                 if s.calibrated and offset_name(s.label) in resolved else s
                 for s in sources)


def reference_zeros(block: JsonObject, coverage: Mapping[str, Any] | None
                    ) -> dict[int, str]:
    """What a reference recorded from a run keeps of each joint's zero (`joint_zeros`):
    "measured" if the run calibrated it from its measurements or through a reference that
    had measured it, else "as_found" (a reference's "as_found" / "unknown" is carried on).
    block: the run's outcome block; coverage: its plan's joint coverage (an older run
    whose rows lack `zero_from` and whose plan took the joint from a reference: unknown)."""
    from_reference = set((coverage or {}).get("from_reference") or ())
    zeros: dict[int, str] = {}
    for row in block.get("joints", []):
        if not isinstance(row, Mapping):
            continue
        joint = int(row["joint"])
        zero = row.get("zero_from")
        if row.get("status") != "calibrated":
            zeros[joint] = "as_found"
        elif isinstance(zero, Mapping):
            zeros[joint] = str(zero.get("reference_zero") or "unknown")
        elif zero is None and f"J{joint}" in from_reference:
            zeros[joint] = "unknown"
        else:
            zeros[joint] = "measured"
    return zeros


def joint_names(joints: Sequence[JointOutcome] | Sequence[JointSource],
                numbers: Sequence[int]) -> str:
    """J2-J5, J1, J6 (a kinematic tree's labels as they are)."""
    by_number = {j.joint: j.label for j in joints}
    labels = [by_number.get(n, f"q{n}") for n in numbers]
    if any(label != f"q{n}" for n, label in zip(numbers, labels, strict=True)):
        return ", ".join(labels)
    parts: list[str] = []
    run: list[int] = []
    for n in sorted(numbers):
        if run and n == run[-1] + 1:
            run.append(n)
            continue
        if run:
            parts.append(_span(run))
        run = [n]
    if run:
        parts.append(_span(run))
    return ", ".join(parts)


def _span(run: list[int]) -> str:
    return f"J{run[0]}" if len(run) == 1 else (
        f"J{run[0]}, J{run[1]}" if len(run) == 2 else f"J{run[0]}-J{run[-1]}")


def derive_outcome(events: Sequence[JsonObject], sources: Sequence[JointSource], *,
                   run_dir: str, finished: bool, required: Sequence[int] = (),
                   new_run: str = "--robot ROBOT", known: Sequence[str] = (),
                   swapped: Sequence[int] = (), host_offsets: str | None = None,
                   archive: str | None = None, simulated: bool = False) -> RobotOutcome:
    """The outcome from the journal's events (`Journal.timeline(*JOURNAL_KINDS)`, in
    order) and the fit's per-joint sources. finished: the run wrote (or is writing) its
    result; run_dir / new_run / known: for the next command (new_run: a new run's
    options for this robot and cell, `RunHeader.new_run_options`; known: the run's known
    frames, kept in a new run's `--known`); swapped: the joints declared swapped
    (`--swapped`): one this run did not calibrate has an unknown zero, so no reference is
    proposed from this run (`unknown_swapped_zeros`); host_offsets: for a robot that keeps
    no zero offsets, how to keep the offsets its driver applied on the host ({run}: the run
    folder; `Driver.host_offsets`), None: the controller keeps what is pushed; archive: the
    results archive the run is archived in (`--db`, without a password): a rollback or a
    resume the next command names keeps it (`--db`), so the archive follows; simulated: the
    run's controller was `--robot sim`, which ended with the run (nothing to roll back)."""
    state = _replay(events)
    host_only = host_offsets is not None
    active = state.pushed_new is not None and state.rolled_at is None
    pushed_mask = state.pushed_mask if active else ()
    joints = []
    rolled_back = not active and state.rolled_at is not None
    for s in sources:
        pushed = bool(active and (s.joint - 1 < len(pushed_mask) and pushed_mask[s.joint - 1]))
        verified = state.verified if pushed else None
        # rolled back: every zero is the previous one again, whatever the fit found
        calibrated = s.calibrated and verified is not False and not rolled_back
        reason = s.reason if not s.calibrated else (
            None if calibrated else
            "rolled back: its zero is the one before the run" if rolled_back else
            "its pushed offset failed verification")
        joints.append(JointOutcome(s.joint, s.label,
                                   "calibrated" if calibrated else "not_calibrated",
                                   s.source, pushed and not host_only, verified, reason,
                                   s.fix if not s.calibrated else None,
                                   s.restored_from, s.reference_zero, pushed and host_only))
    required = tuple(sorted(set(required)))
    missing = tuple(n for n in required
                    if not any(j.joint == n and j.source == "data" for j in joints))
    if not finished:
        verdict = "ERROR"
    elif active and state.verified is False:
        verdict = "FAIL"
    elif not active and state.rolled_at is not None:
        verdict = "ROLLED_BACK"
    elif not active and state.refused is not None:
        verdict = "REFUSED"
    elif missing:
        verdict = "JOINTS_MISSING"
    elif active:
        verdict = "PASS" if state.verified else "NOT_VERIFIED"
    else:
        verdict = "NOT_PUSHED"
    controller = _controller_text(state, active)
    if host_only and active:
        keep = (host_offsets or "").format(run=run_dir)
        controller = (f"zero offsets unchanged: the new ones are applied on the host for "
                      f"this session only ({controller.split(', ', 1)[1]}); to keep them: "
                      f"{keep}")
    outcome = RobotOutcome(
        verdict=verdict, controller=controller, pushed=active and not host_only,
        applied_on_host=active and host_only,
        verified=state.verified if active else None, rolled_back_at=state.rolled_at,
        joints=tuple(joints), required_joints=required, missing_required=missing,
        headline="", next_command=None, events=tuple(state.events),
        refused_reason=state.refused, refusal=state.refusal if state.refused else None)
    outcome = _with_words(outcome, run_dir, new_run, tuple(known), state.intent_open,
                          tuple(swapped), simulated)
    command = outcome.next_command
    return dataclasses.replace(outcome, archive=archive, next_command=(
        None if command is None else with_archive(command, archive)))


@dataclass
class _Replay:
    pushed_new: np.ndarray | None = None
    pushed_mask: tuple[bool, ...] = ()
    verified: bool | None = None
    rolled_at: str | None = None
    refused: str | None = None
    refusal: PushRefusal | None = None
    intent_open: bool = False
    events: list[OutcomeEvent] = field(default_factory=list)


def _replay(events: Sequence[JsonObject]) -> _Replay:
    """Walk the journal's events in order: the last push, whether it was verified or
    rolled back since, a refusal after it."""
    state = _Replay()
    for e in events:
        kind = e.get("event")
        at = e.get("time") or e.get("at")
        if kind == "push_intent":
            state.intent_open = True
        elif kind == "push":
            state.pushed_new = np.asarray(e.get("new_offsets", ()), float)
            state.pushed_mask = tuple(bool(v) for v in e.get("pushed", ()))
            state.verified, state.rolled_at, state.refused = None, None, None
            state.intent_open = False
            state.events.append(OutcomeEvent(at, "pushed", (
                ("rollback_id", e.get("rollback_id")),
                ("recovered", bool(e.get("recovered", False))))))
        elif kind == "verify":
            offsets = np.asarray(e.get("offsets", ()), float)
            judged = (state.pushed_new is not None and state.rolled_at is None
                      and offsets.shape == state.pushed_new.shape
                      and bool(np.allclose(offsets, state.pushed_new, rtol=0.0, atol=_MATCH)))
            details = (("verdict", e.get("verdict")), ("p_value", e.get("p_value")))
            if judged:
                state.verified = e.get("verdict") == "PASS"
            state.events.append(OutcomeEvent(at, "verified" if judged else "model_check",
                                             details))
        elif kind == "rollback":
            if state.pushed_new is not None:
                state.rolled_at = str(at or "an unrecorded time")
            state.intent_open = False
            state.events.append(OutcomeEvent(at, "rolled_back", (("how", e.get("how")),)))
        elif kind == "push_refused":
            state.refused = str(e.get("reason") or "refused by a guard rail")
            state.refusal = PushRefusal.from_event(e)
            state.intent_open = False  # refused: the offsets were not written
            state.events.append(OutcomeEvent(at, "refused", (("reason", state.refused),)))
        elif kind == "resumed":
            # a refusal is the decision of one attempt: a resume decides the push anew (and
            # journals its own push_refused if it refuses again), so an earlier refusal no
            # longer speaks for the controller; a push or a rollback did change it and stays
            state.refused = None
            state.events.append(OutcomeEvent(at, "resumed"))
    return state


def _controller_text(state: _Replay, active: bool) -> str:
    if active:
        return {True: "new offsets, verified", False: "new offsets, verification FAILED",
                None: "new offsets, NOT verified"}[state.verified]
    if state.rolled_at is not None:
        return f"offsets restored by rollback at {state.rolled_at}"
    if state.intent_open:
        return "unknown: a push was cut short (a resume settles it from the controller)"
    return "offsets unchanged"


def _with_words(outcome: RobotOutcome, run_dir: str, new_run: str, known: tuple[str, ...],
                intent_open: bool, swapped: tuple[int, ...], simulated: bool = False
                ) -> RobotOutcome:
    """The outcome with its headline and next command filled in."""
    joints = outcome.joints
    good = [j.joint for j in joints if j.calibrated and not j.as_found]
    bad = [j for j in joints if j.source != "data"]
    applied = outcome.pushed or outcome.applied_on_host
    done = ("verified" if outcome.verified else "pushed, NOT verified" if applied
            else "fitted, not pushed")
    good_text = f"{joint_names(joints, good)} calibrated and {done}" if good else \
        "no joint calibrated"
    if outcome.verdict in ("PASS", "NOT_VERIFIED", "JOINTS_MISSING") and not applied:
        good_text = f"{joint_names(joints, good)} fitted from data, not pushed" if good \
            else "no joint fitted from data"
    restored = _restored_text(joints)
    if restored:  # never "calibrated" for a zero the reference only carries over
        good_text = f"{good_text}; {restored}" if good else restored
    if outcome.applied_on_host and outcome.verdict != "FAIL":  # never "the controller holds"
        good_text += ("; applied on the host for this session only: the controller's zero "
                      "offsets are unchanged (" + outcome.controller.split("; ", 1)[1] + ")")
    bad_text = _not_calibrated_text(joints, bad)
    verdict = outcome.verdict
    run = run_dir
    unknown = unknown_swapped_zeros(joints, swapped)
    next_command: str | None = None
    if verdict == "PASS":
        head = f"PASS: {good_text}" + (f"; {bad_text}" if bad_text else "")
    elif verdict == "JOINTS_MISSING":
        missing = joint_names(joints, outcome.missing_required)
        head = f"JOINTS_MISSING: {good_text}; {bad_text} (required: {missing})"
        if unknown:  # a reference from this run would absorb the swapped zero's error
            head += f"; {_unknown_zero_text(joints, unknown)}"
            next_command = _swap_fix_command(joints, outcome, new_run, known, unknown)
        else:
            next_command = _fix_command(joints, outcome, run, new_run, known)
        if next_command is not None and not unknown:  # no reference of this run's zeros
            names = joint_names(joints, [j.joint for j in joints if j.joint in
                                         outcome.missing_required and j.fix])
            head += (f"; {names} need their frames surveyed (--known) or a cell reference "
                     f"recorded from a run that calibrated {names} (a reference recorded "
                     f"from this run keeps this robot's present {names} zeros, whatever "
                     "they are)")
    elif verdict == "NOT_VERIFIED":
        head = f"PUSHED, NOT VERIFIED: {good_text} (no verification poses)" + (
            f"; {bad_text}" if bad_text else "")
    elif verdict == "FAIL" and outcome.applied_on_host:  # nothing to roll back
        head = ("FAIL: the offsets applied on the host (this session only) failed "
                "verification; the controller's zero offsets are unchanged"
                + (f"; {bad_text}" if bad_text else ""))
        next_command = f"hostpc diagnose {run}/dataset.json"
    elif verdict == "FAIL" and simulated:  # its controller ended with the run
        head = ("FAIL: the pushed offsets failed verification; the simulated controller "
                "held them and ended with the run (nothing to roll back)"
                + (f"; {bad_text}" if bad_text else ""))
        next_command = f"hostpc diagnose {run}/dataset.json --ladder"
    elif verdict == "FAIL":
        head = ("FAIL: the pushed offsets failed verification; the controller holds them"
                + (f"; {bad_text}" if bad_text else ""))
        next_command = rollback_command(run)
    elif verdict == "ROLLED_BACK":
        head = (f"ROLLED BACK at {outcome.rolled_back_at}: the controller has its previous "
                "offsets again")
        next_command = resume_command(run, "--push")
    elif verdict == "REFUSED":
        head = f"REFUSED: push refused, offsets unchanged ({outcome.refused_reason})"
        constrained = _constraints_text(joints)
        if constrained and outcome.refusal is not None and outcome.refusal.rule in (
                "not_converged", "model"):  # the user's own constraints come first
            head += (f"; the fit failed with {constrained}: a likely cause; run again "
                     "without them or check them")
        next_command = (outcome.refusal.next_command(run) if outcome.refusal is not None
                        else _legacy_refusal_command(outcome.refused_reason or "", run))
    elif verdict == "NOT_PUSHED":
        head = f"NOT PUSHED: offsets unchanged; {good_text}" + (
            f"; {bad_text}" if bad_text else "")
        next_command = resume_command(run, "--push") if good else None
        if _model_check_failed(outcome.events):
            # the push would be refused for the same reason: find the missing effect first
            head += "; the model does not explain fresh poses (model check FAIL)"
            next_command = f"hostpc diagnose {run}/dataset.json --ladder"
    else:
        head = f"ERROR: the run did not finish; controller: {outcome.controller}"
        next_command = resume_command(run)
    if intent_open and verdict == "ERROR":
        next_command = resume_command(run)
    return dataclasses.replace(outcome, headline=head, next_command=next_command,
                               unknown_zeros=unknown)


def _restored_text(joints: Sequence[JointOutcome]) -> str:
    """"J1, J6 restored to the cell reference of RUN (their zeros as at that run, ...)":
    the joints only a reference identifies whose recording run did not calibrate them."""
    groups: dict[tuple[str, str], list[int]] = {}
    for j in joints:
        if j.as_found:
            groups.setdefault((str(j.restored_from), str(j.reference_zero)), []).append(j.joint)
    parts = []
    for (run, zero), numbers in groups.items():
        their = "its zero" if len(numbers) == 1 else "their zeros"
        why = (f"{their} as at that run, not measured against a surveyed frame"
               if zero == "as_found" else
               f"whether that run calibrated them is not recorded (a reference from before "
               f"zerocal kept it): {their} may be as at that run")
        parts.append(f"{joint_names(joints, numbers)} restored to the cell reference of "
                     f"{run} ({why})")
    return "; ".join(parts)


def _constraints_text(joints: Sequence[JointOutcome]) -> str:
    """"J3 held and a prior on J2": the joints the user's --hold / --prior decided."""
    held = [j.joint for j in joints if j.source == "hold"]
    prior = [j.joint for j in joints if j.source == "prior"]
    parts = ([f"{joint_names(joints, held)} held"] if held else []) + (
        [f"a prior on {joint_names(joints, prior)}"] if prior else [])
    return " and ".join(parts)


def _legacy_refusal_command(reason: str, run: str) -> str:
    """The next command of a refusal journaled without its structured form (an older
    zerocal's journal), from the refusal's words."""
    swapped = _LEGACY_SWAP_HINT.search(reason)
    if "hostpc diagnose" in reason:
        return f"hostpc diagnose {run}/dataset.json"
    if "controller's own offset limit" in reason:  # --force would meet it again
        return resume_command(run, "--push")
    if swapped is not None:
        return resume_command(run, "--swapped", swapped.group(1))
    return resume_command(run, "--force")


def _model_check_failed(events: Sequence[OutcomeEvent]) -> bool:
    """True if the last check of the fitted model on fresh poses (nothing pushed) failed."""
    checks = [dict(e.details) for e in events if e.event == "model_check"]
    return bool(checks) and checks[-1].get("verdict") == "FAIL"


def _not_calibrated_text(joints: Sequence[JointOutcome], bad: Sequence[JointOutcome]) -> str:
    """"J1, J6 NOT CALIBRATED (unidentifiable: ...)" grouped by reason."""
    if not bad:
        return ""
    by_reason: dict[str, list[int]] = {}
    for j in bad:
        by_reason.setdefault(_short_reason(j), []).append(j.joint)
    return "; ".join(f"{joint_names(joints, numbers)} NOT CALIBRATED ({reason})"
                     for reason, numbers in by_reason.items())


def _short_reason(joint: JointOutcome) -> str:
    reason = joint.reason or "not calibrated"
    if joint.source == "hold":
        return "held by --hold"
    if joint.source == "prior":
        return "prior value, not measured"
    if reason.startswith("unidentifiable with the "):
        return "unidentifiable: " + reason[len("unidentifiable with the "):].split(" (")[0]
    return reason.split(" (")[0]


def unknown_swapped_zeros(joints: Sequence[JointOutcome] | Sequence[JointSource],
                          swapped: Sequence[int]) -> tuple[int, ...]:
    """The joints declared swapped (`--swapped`) that the run did not calibrate: their
    zeros are unknown, and every frame the run estimated carries their error (a reference
    recorded from the run would take it for the cell's geometry)."""
    calibrated = {j.joint for j in joints if j.calibrated}
    return tuple(sorted({int(n) for n in swapped} - calibrated))


def _unknown_zero_text(joints: Sequence[JointOutcome], unknown: Sequence[int]) -> str:
    names = joint_names(joints, unknown)
    return (f"{names} declared swapped and not calibrated: its zero is unknown, so this "
            "run's frames carry its error and a reference recorded from this run would "
            f"hide it; calibrate {names} with a reference recorded before the swap, a "
            "surveyed frame, or the robot maker's zeroing procedure")


def _swap_fix_command(joints: Sequence[JointOutcome], outcome: RobotOutcome, new_run: str,
                      known: tuple[str, ...], unknown: Sequence[int]) -> str:
    """The honest ways to calibrate a swapped joint this run could not: a new run with a
    reference recorded before the swap, or with the frame it needs surveyed (`--known`),
    or the robot maker's zeroing procedure (never a reference from this run)."""
    required = _required_text(joints, outcome)
    frames = [f for f in known if f != "none"]
    kept = f" --known {','.join(frames)}" if frames else ""
    needed = _frames_needed(joints, unknown, frames)
    names = joint_names(joints, unknown)
    ways = [f"hostpc calibrate {new_run}{kept} --reference REFERENCE_FROM_BEFORE_THE_SWAP.json "
            f"--require-joints {required}"]
    if needed != frames:
        surveyed = " and ".join(f for f in needed if f not in frames)
        ways.append(f"hostpc calibrate {new_run} --known {','.join(needed)} --require-joints "
                    f"{required} (with the {surveyed} frame surveyed)")
    ways.append(f"set {names} with the robot maker's zeroing procedure")
    return ", or ".join(ways)


def _frames_needed(joints: Sequence[JointOutcome], numbers: Sequence[int],
                   frames: Sequence[str]) -> list[str]:
    """The run's surveyed `frames` and those the fixes of joints `numbers` name
    (`--known target`)."""
    needed = list(frames)
    for j in joints:
        match = _KNOWN_FIX.search(j.fix or "") if j.joint in numbers else None
        for frame in match.group(1).split(",") if match else ():
            if frame not in needed:
                needed.append(frame)
    return needed


def _required_text(joints: Sequence[JointOutcome], outcome: RobotOutcome) -> str:
    return ("all" if len(outcome.required_joints) == len(joints)
            else ",".join(str(n) for n in outcome.required_joints))


def _fix_command(joints: Sequence[JointOutcome], outcome: RobotOutcome, run: str,
                 new_run: str, known: tuple[str, ...]) -> str | None:
    """The honest ways to calibrate the missing joints: a new run with the frames they
    trade against surveyed (`--known`), or with a cell reference recorded from a run that
    calibrated them. Never a reference recorded from THIS run as the way: it would keep
    this robot's present zeros of those joints, and later runs would restore them to those
    (on a station every robot is new: they are no robot's known-good zeros)."""
    missing = [j for j in joints if j.joint in outcome.missing_required and j.fix]
    if not missing:
        return None
    required = _required_text(joints, outcome)
    frames = [f for f in known if f != "none"]  # the run's own surveyed frames stay known
    kept = f" --known {','.join(frames)}" if frames else ""
    needed = _frames_needed(joints, [j.joint for j in missing], frames)
    names = joint_names(joints, [j.joint for j in missing])
    if needed == frames:  # no frame would identify them (a hold, a prior): no reference
        return None
    surveyed = " and ".join(f for f in needed if f not in frames)
    ways = [f"hostpc calibrate {new_run} --known {','.join(needed)} --require-joints "
            f"{required} (with the {surveyed} frame surveyed)",
            f"hostpc calibrate {new_run}{kept} --reference CELL_REFERENCE.json "
            f"--require-joints {required} (CELL_REFERENCE.json: hostpc reference record "
            f"--run RUN of a run that calibrated {names}: with those frames surveyed, or on "
            "a robot whose zeros the maker's mastering set; recorded from this run "
            f"({run}) it keeps this robot's present {names} zeros and later runs restore "
            f"{names} to them)"]
    return ", or ".join(ways)
