"""The journal's events as typed values: one frozen dataclass per event kind.

A run appends them (``Journal.append``) and reads them back by type (``Journal.events``,
``Journal.last_event``). ``to_json`` is the event's journal line without its ``"event"``
key, its keys in the order they have always been written (a journal line stays
byte-identical); ``from_json`` reads a line back, also one an older version wrote: a key
the reader does not use may be absent and takes its default. The line codec itself
(`json.loads`/`json.dumps`, the torn-tail rule, the offsets check that refuses a broken
line) is ``hostpc.calibrate.journal``.

Offsets are radians; ``at`` / ``time`` are ISO 8601 UTC times.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, ClassVar, Protocol

import numpy as np

from hostpc.json_object import JsonObject


class JournalEvent(Protocol):
    """A non-sample journal event: its kind (the line's ``"event"``) and its JSON form."""

    kind: ClassVar[str]

    def to_json(self) -> JsonObject:
        """The event's fields, in the order the journal line has them."""
        ...


def _floats(values: Any) -> tuple[float, ...]:
    return tuple(float(v) for v in values)


def _int(value: Any, default: int = 0) -> int:
    """A JSON integer; `default` for anything else (a field no reader relies on)."""
    return value if isinstance(value, int) and not isinstance(value, bool) else default


def _number(value: Any) -> float:
    """A JSON number as a float; NaN for anything else (the reader skips it)."""
    return float(value) if isinstance(value, int | float) else float("nan")


@dataclass(frozen=True)
class PushRecord:
    """What was written: previous offsets (n,) rad (the ones the host read before the
    write, never the controller's claim) and new ones (the ones asked for), the
    controller's rollback id (None for a push recovered from its intent: the id was never
    received), which joints changed, and when (ISO 8601, UTC).

    A controller whose report of the write disagrees (hostpc.calibrate.push, PushMismatch)
    adds what it said: ``held`` (n,) rad, the offsets read back after the write when they
    are not the new ones (it clamped or ignored them), ``reported_previous`` (n,) rad, the
    previous offsets its reply named when they are not the ones read before; None when
    they agree (and absent from the JSON form, whose lines then stay as they were)."""

    previous: np.ndarray
    new: np.ndarray
    rollback_id: str | None
    pushed: tuple[bool, ...]
    time: str = ""
    held: np.ndarray | None = None
    reported_previous: np.ndarray | None = None

    @property
    def inconsistent(self) -> bool:
        """True if the controller's report of the write disagreed (see the class)."""
        return self.held is not None or self.reported_previous is not None

    def to_dict(self) -> JsonObject:
        """JSON form (radians): the journal's `push` event and push.json."""
        extra: JsonObject = {}
        if self.held is not None:
            extra["held_offsets"] = self.held.tolist()
        if self.reported_previous is not None:
            extra["reported_previous_offsets"] = self.reported_previous.tolist()
        return {
            "rollback_id": self.rollback_id,
            "previous_offsets": self.previous.tolist(),
            "new_offsets": self.new.tolist(),
            "pushed": list(self.pushed),
            "time": self.time,
            **extra,
        }

    @classmethod
    def from_dict(cls, data: JsonObject) -> PushRecord:
        """Inverse of to_dict (push.json, a `push` or `push_intent` event)."""
        rollback_id = data.get("rollback_id")
        held, reported = data.get("held_offsets"), data.get("reported_previous_offsets")
        return cls(previous=np.asarray(data["previous_offsets"], float),
                   new=np.asarray(data["new_offsets"], float),
                   rollback_id=None if rollback_id is None else str(rollback_id),
                   pushed=tuple(bool(v) for v in data.get("pushed", ())),
                   time=str(data.get("time", "")),
                   held=None if held is None else np.asarray(held, float),
                   reported_previous=None if reported is None else np.asarray(reported, float))


@dataclass(frozen=True)
class PushIntent:
    """Written before the controller's offsets are: the push it means to make."""

    kind: ClassVar[str] = "push_intent"
    record: PushRecord  # rollback_id None: not received yet

    def to_json(self) -> JsonObject:
        fields = self.record.to_dict()
        del fields["rollback_id"]
        return fields

    @classmethod
    def from_json(cls, data: JsonObject) -> PushIntent:
        return cls(PushRecord.from_dict(data))


@dataclass(frozen=True)
class Pushed:
    """The controller's offsets were written; recovered: settled on a resume from the
    controller's offsets (the push cut short after its intent)."""

    kind: ClassVar[str] = "push"
    record: PushRecord
    recovered: bool = False

    def to_json(self) -> JsonObject:
        return {**self.record.to_dict(), **({"recovered": True} if self.recovered else {})}

    @classmethod
    def from_json(cls, data: JsonObject) -> Pushed:
        return cls(PushRecord.from_dict(data), bool(data.get("recovered", False)))


@dataclass(frozen=True)
class PushWritten:
    """The controller answered the write of the last `push_intent` (its rollback id, when,
    ISO 8601 UTC) and the read-back of its offsets has not come yet: written before that
    read, so a read-back that fails still leaves the id (`hostpc rollback --run DIR`
    undoes the write with it). The `push` event follows once the read-back came."""

    kind: ClassVar[str] = "push_written"
    rollback_id: str
    time: str = ""

    def to_json(self) -> JsonObject:
        return {"rollback_id": self.rollback_id, "time": self.time}

    @classmethod
    def from_json(cls, data: JsonObject) -> PushWritten:
        return cls(str(data["rollback_id"]), str(data.get("time", "")))


@dataclass(frozen=True)
class PushRefused:
    """A guard rail (by None) or the controller (by "controller") refused the push."""

    kind: ClassVar[str] = "push_refused"
    reason: str | None
    at: str
    by: str | None = None

    def to_json(self) -> JsonObject:
        return {"reason": self.reason, **({"by": self.by} if self.by is not None else {}),
                "at": self.at}

    @classmethod
    def from_json(cls, data: JsonObject) -> PushRefused:
        by = data.get("by")
        return cls(data.get("reason"), str(data.get("at", "")),
                   None if by is None else str(by))


@dataclass(frozen=True)
class Rollback:
    """`hostpc rollback` undid the run's push: how, on which controller, the offsets the
    controller has after it."""

    kind: ClassVar[str] = "rollback"
    how: str
    controller: str
    offsets: tuple[float, ...]
    time: str | None  # None in a line that lacks it

    def to_json(self) -> JsonObject:
        return {"how": self.how, "controller": self.controller, "offsets": list(self.offsets),
                "time": self.time}

    @classmethod
    def from_json(cls, data: JsonObject) -> Rollback:
        time = data.get("time")
        return cls(str(data.get("how", "")), str(data.get("controller", "")),
                   _floats(data["offsets"]), None if time is None else str(time))


@dataclass(frozen=True)
class VerifyStart:
    """A verification round starts: its number, its first pose index, the offsets it
    verifies and the delta pushed before it."""

    kind: ClassVar[str] = "verify_start"
    round: int
    first: int
    offsets: tuple[float, ...]
    pushed_delta: tuple[float, ...]

    def to_json(self) -> JsonObject:
        return {"round": self.round, "first": self.first, "offsets": list(self.offsets),
                "pushed_delta": list(self.pushed_delta)}

    @classmethod
    def from_json(cls, data: JsonObject) -> VerifyStart:
        return cls(int(data["round"]), int(data["first"]), _floats(data["offsets"]),
                   _floats(data["pushed_delta"]))


@dataclass(frozen=True)
class Verified:
    """A verification round's verdict on the offsets the controller had."""

    kind: ClassVar[str] = "verify"
    round: int
    verdict: str
    at: str
    statistic: float | None
    dof: int
    p_value: float | None
    offsets: tuple[float, ...]

    def to_json(self) -> JsonObject:
        return {"round": self.round, "verdict": self.verdict, "at": self.at,
                "statistic": self.statistic, "dof": self.dof, "p_value": self.p_value,
                "offsets": list(self.offsets)}

    @classmethod
    def from_json(cls, data: JsonObject) -> Verified:
        statistic, p_value = data.get("statistic"), data.get("p_value")
        return cls(_int(data.get("round")), str(data.get("verdict", "")),
                   str(data.get("at", "")), _number(statistic) if statistic is not None else None,
                   _int(data.get("dof")), _number(p_value) if p_value is not None else None,
                   _floats(data["offsets"]))


@dataclass(frozen=True)
class VerifyRoundLost:
    """Every pose of a verification round was skipped."""

    kind: ClassVar[str] = "verify_lost"
    round: int

    def to_json(self) -> JsonObject:
        return {"round": self.round}

    @classmethod
    def from_json(cls, data: JsonObject) -> VerifyRoundLost:
        return cls(_int(data.get("round")))


@dataclass(frozen=True)
class RunFinished:
    """The run wrote its result: exit code, push status, verification verdict, outcome
    verdict, and the controller's offsets at the end."""

    kind: ClassVar[str] = "result"
    exit_code: int
    push: str
    verdict: str | None
    outcome: str
    at: str
    offsets: tuple[float, ...]

    def to_json(self) -> JsonObject:
        return {"exit_code": self.exit_code, "push": self.push, "verdict": self.verdict,
                "outcome": self.outcome, "at": self.at, "offsets": list(self.offsets)}

    @classmethod
    def from_json(cls, data: JsonObject) -> RunFinished:
        verdict = data.get("verdict")
        return cls(_int(data.get("exit_code")), str(data.get("push", "")),
                   None if verdict is None else str(verdict), str(data.get("outcome", "")),
                   str(data.get("at", "")), _floats(data["offsets"]))


@dataclass(frozen=True)
class Resumed:
    """A session resumed the run."""

    kind: ClassVar[str] = "resumed"
    at: str

    def to_json(self) -> JsonObject:
        return {"at": self.at}

    @classmethod
    def from_json(cls, data: JsonObject) -> Resumed:
        return cls(str(data.get("at", "")))


@dataclass(frozen=True)
class MorePoses:
    """The fit did not explain its measurements: the plan grew by n poses (more_poses.py)."""

    kind: ClassVar[str] = "more_poses"
    reason: str
    n: int

    def to_json(self) -> JsonObject:
        return {"reason": self.reason, "n": self.n}

    @classmethod
    def from_json(cls, data: JsonObject) -> MorePoses:
        return cls(str(data.get("reason", "asked before")), _int(data.get("n")))


@dataclass(frozen=True)
class RobotTimeSpent:
    """Robot time (s) of one phase since the clock's last reading, by the controller's
    or the host's clock (robot_time.py); seconds NaN in a line that lacks a number. at: the
    controller clock's reading (s) that ended it (None: the host's clock, or an older run)."""

    kind: ClassVar[str] = "robot_time"
    phase: str
    seconds: float
    clock: str
    at: float | None = None

    def to_json(self) -> JsonObject:
        at = {} if self.at is None else {"at": self.at}
        return {"phase": self.phase, "seconds": self.seconds, "clock": self.clock, **at}

    @classmethod
    def from_json(cls, data: JsonObject) -> RobotTimeSpent:
        at = data.get("at")
        return cls(str(data.get("phase", "")), _number(data.get("seconds")),
                   str(data.get("clock", "controller")),
                   None if at is None else _number(at))


@dataclass(frozen=True)
class Stage:
    """A swap stage (swaps.py): its number, first pose index and the joint offset estimate
    (n,) rad its poses are shifted by."""

    kind: ClassVar[str] = "stage"
    number: int
    first: int
    at: str
    estimate: tuple[float, ...]

    def to_json(self) -> JsonObject:
        return {"number": self.number, "first": self.first, "at": self.at,
                "estimate": list(self.estimate)}

    @classmethod
    def from_json(cls, data: JsonObject) -> Stage:
        return cls(int(data["number"]), int(data["first"]), str(data.get("at", "")),
                   _floats(data["estimate"]))


@dataclass(frozen=True)
class Note:
    """A remark for the reader of the journal (nothing reads it back): its text and the
    facts it names (a reference file and when it was recorded, the known frames, the
    settings a resume changed, the clock's last t and origin, a t shift)."""

    kind: ClassVar[str] = "note"
    text: str
    reference: str | None = None
    recorded: str | None = None
    known: tuple[str, ...] | None = None
    overrides: JsonObject | None = None  # the changed settings, in their JSON form
    last_t: float | None = None
    time_origin: float | None = None
    t_shift: float | None = None

    def to_json(self) -> JsonObject:
        facts = {"reference": self.reference, "recorded": self.recorded,
                 "known": None if self.known is None else list(self.known),
                 "overrides": self.overrides, "last_t": self.last_t,
                 "time_origin": self.time_origin, "t_shift": self.t_shift}
        return {"text": self.text, **{k: v for k, v in facts.items() if v is not None}}

    @classmethod
    def from_json(cls, data: JsonObject) -> Note:
        def text(key: str) -> str | None:
            value = data.get(key)
            return None if value is None else str(value)

        def number(key: str) -> float | None:
            value = data.get(key)
            return None if value is None else _number(value)

        known, overrides = data.get("known"), data.get("overrides")
        return cls(str(data.get("text", "")), text("reference"), text("recorded"),
                   tuple(str(k) for k in known) if isinstance(known, list) else None,
                   overrides if isinstance(overrides, dict) else None,
                   number("last_t"), number("time_origin"), number("t_shift"))


EVENT_TYPES: tuple[type[Any], ...] = (PushIntent, PushWritten, Pushed, PushRefused, Rollback,
                                      VerifyStart, Verified, VerifyRoundLost, RunFinished,
                                      Resumed, MorePoses, RobotTimeSpent, Stage, Note)
"""Every event kind a run writes."""
_READERS: dict[str, Callable[[JsonObject], JournalEvent]] = {
    kind.kind: kind.from_json for kind in EVENT_TYPES}


def event_from_json(data: JsonObject) -> JournalEvent | None:
    """A journal line's event as its typed value (None for a kind this version does not
    write); KeyError / TypeError / ValueError if a field it needs is broken."""
    reader = _READERS.get(str(data.get("event")))
    return None if reader is None else reader(data)
