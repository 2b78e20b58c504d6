"""push.json, a run folder's record of its push (`hostpc.calibrate.push.execute_push`),
validated at the file edge before `hostpc rollback --run DIR` writes a controller from it.

The rollback writes `previous_offsets` into the controller, so nothing in the file is
trusted (as FIT.json, hostpc.calibrate.fit_file):

- the JSON itself (`parse_strict_json`): no duplicated key, no NaN / Infinity literal, no
  endless nesting or digits; strict types (pydantic, strict mode);
- `status` "intent" (written before the controller was) or "pushed" (then `rollback_id`
  is a string, unless `recovered`: a push a resume settled from its intent);
- `previous_offsets` and `new_offsets`: lists of finite numbers, as many of each, every
  one below half a turn (`MAX_JOINT_OFFSET_RAD`, rad); `pushed` one boolean per joint, and
  a joint not pushed has the same previous and new offset;
- the run's journal (when the folder has one) holds the same push: its last `push` or
  `push_intent` event names the same previous and new offsets (a push.json edited by hand,
  or copied from another run, disagrees with it).

The joint count is the controller's (`check_joint_count`, once the rollback has read the
controller's offsets). A bad file raises InputError (exit code 2) with one line naming the
file and the field; nothing is written to the controller.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Literal

import numpy as np
from pydantic import Field, StrictBool, StrictStr

from hostpc.calibrate.fit_file import MAX_JOINT_OFFSET_RAD
from hostpc.calibrate.journal import Journal
from hostpc.calibrate.journal_events import Pushed, PushIntent, PushRecord
from hostpc.calibrate.push import PUSH_FILE, same_offsets
from hostpc.calibrate.strict_json import StrictFile, parse_strict_json, validate_strict
from hostpc.errors import InputError
from hostpc.input_files import CONFIG, read_input_text

Offset = Annotated[float, Field(allow_inf_nan=False, ge=-MAX_JOINT_OFFSET_RAD,
                                le=MAX_JOINT_OFFSET_RAD)]
Finite = Annotated[float, Field(allow_inf_nan=False)]


class PushDocument(StrictFile):
    """The fields of push.json (`PushRecord.to_dict` plus `controller`, `status`,
    `recovered`); unknown keys ignored."""

    controller: StrictStr | None = None
    status: Literal["intent", "pushed"] = "pushed"
    rollback_id: StrictStr | None = None
    previous_offsets: Annotated[list[Offset], Field(min_length=1)]
    new_offsets: Annotated[list[Offset], Field(min_length=1)]
    pushed: list[StrictBool] = []
    time: StrictStr = ""
    recovered: StrictBool = False
    held_offsets: list[Finite] | None = None  # the controller's word, never written back
    reported_previous_offsets: list[Finite] | None = None


@dataclass(frozen=True)
class PushFile:
    """A validated push.json: the controller it was pushed to (None if unrecorded), its
    status ("intent" or "pushed") and the push itself."""

    controller: str | None
    status: str
    record: PushRecord


def _remedy(run_dir: Path, document: object = None) -> str:
    """What to do about a bad push.json; `document`: the file's JSON, for the controller's
    address when it names one."""
    controller = document.get("controller") if isinstance(document, dict) else None
    address = controller if isinstance(controller, str) and controller else "HOST"
    return (f"push.json is written by hostpc, never by hand (the journal.jsonl of "
            f"{run_dir} keeps the push as made); see what the controller holds with: "
            f"hostpc status --robot {address}")


def read_push_file(run_dir: str | Path) -> PushFile:
    """The push record of a run folder, validated (see the module docstring); InputError
    if the run pushed nothing or the file is not a push record this run made."""
    run_dir = Path(run_dir)
    path = run_dir / PUSH_FILE
    if not os.path.lexists(path):
        raise InputError(f"{run_dir}: this run pushed no offsets (no {PUSH_FILE})")
    source = str(path)
    document = parse_strict_json(read_input_text(path, CONFIG, source), source,
                                 _remedy(run_dir))
    if not isinstance(document, dict):
        raise InputError(f"{source}: expected a JSON object, got {type(document).__name__}; "
                         f"{_remedy(run_dir)}")
    remedy = _remedy(run_dir, document)
    push = validate_strict(PushDocument, document, source, remedy)
    problem = _problem(push)
    if problem:
        raise InputError(f"{source}: {problem}; {remedy}")
    record = PushRecord.from_dict(document)
    _check_journal(record, source, remedy, Journal(run_dir))
    return PushFile(push.controller, push.status, record)


def _problem(push: PushDocument) -> str:
    """Why the fields of a well-typed push.json disagree with each other ("" if not)."""
    n = len(push.previous_offsets)
    if push.status == "pushed" and push.rollback_id is None and not push.recovered:
        return ('rollback_id: required for status "pushed" (the controller\'s id of the '
                'write; none only for a push a resume recovered, "recovered": true)')
    if len(push.new_offsets) != n:
        return (f"new_offsets: {len(push.new_offsets)} offsets, previous_offsets has {n}: "
                "one of each per joint")
    if push.pushed and len(push.pushed) != n:
        return f"pushed: {len(push.pushed)} entries for {n} joints"
    for j, changed in enumerate(push.pushed):
        before, after = push.previous_offsets[j], push.new_offsets[j]
        if not changed and not same_offsets([before], [after]):
            return (f"new_offsets[{j}]: joint J{j + 1} is not pushed, yet its new offset "
                    f"{math.degrees(after):+.5f} deg is not its previous one "
                    f"{math.degrees(before):+.5f} deg")
    return ""


def _check_journal(record: PushRecord, source: str, remedy: str, journal: Journal) -> None:
    """InputError if the run's journal holds another push than push.json."""
    if not journal.exists or not journal.journal_path.is_file():
        return
    last = journal.last_event(PushIntent, Pushed)
    if not isinstance(last, PushIntent | Pushed):
        return  # the journal's lines of the push were lost (torn): push.json is all there is
    made = last.record
    for name, kept, journaled in (("previous_offsets", record.previous, made.previous),
                                  ("new_offsets", record.new, made.new)):
        if not same_offsets(kept, journaled):
            raise InputError(
                f"{source}: {name} {_degrees(kept)} deg is not the journal's "
                f"{_degrees(journaled)} deg (its last {type(last).kind} event): push.json "
                f"was changed after the push; nothing written; {remedy}")


def _degrees(offsets: np.ndarray) -> str:
    return "[" + ", ".join(f"{math.degrees(float(v)):+.5f}" for v in offsets) + "]"


def check_joint_count(push: PushFile, n_controller: int, run_dir: str | Path,
                      address: str) -> None:
    """InputError if the push record has another joint count than the controller it would
    be written to (nothing written)."""
    n = push.record.previous.size
    if n != n_controller:
        raise InputError(
            f"{Path(run_dir) / PUSH_FILE}: {n} offsets, the controller at {address} has "
            f"{n_controller} joints: not this controller's push; nothing written; give the "
            "controller the run pushed to with --robot HOST[:PORT]")
