"""The run folder's journal: nothing measured is ever lost, nothing is measured twice.

Files in the run folder DIR:

- `run.json`   the run's header, rewritten atomically (temp file + fsync + rename) as
               stages complete: format tag, robot address and driver, settings, seed,
               cell, the controller's state and offsets at the start, and the plan once it
               exists. A resume reads everything from here.
- `journal.jsonl`
               append-only, one JSON object per line, each line flushed and fsync'ed before
               the next pose: `{"event": "sample", "phase": "fit"|"verify", "index": i,
               "status": "ok"|"skipped", "sample": {...}, "reason": ...}` and the other
               events of the run (`push_intent` written before the controller's offsets
               are, `push` after, `note`). Samples are keyed by (phase, index): a
               record already present is never replaced, so a resume neither repeats nor
               loses a pose (a pose journaled as skipped may be measured again: the later record
               replaces it). A torn last line (power cut mid-write) is ignored on reading
               and cut off before the next append.

Everything is in SI units and radians.
"""

from __future__ import annotations

import json
import os
from collections.abc import Iterator
from pathlib import Path
from typing import Any, TypeVar, overload

from hostpc.calibrate.journal_events import JournalEvent, event_from_json
from hostpc.errors import InputError
from hostpc.files import write_json_atomic
from hostpc.json_object import JsonObject
from hostpc.methods.base import SampleRecord

RUN_FORMAT = "zerocal-run/1"
RUN_FILE = "run.json"
JOURNAL_FILE = "journal.jsonl"

EventT = TypeVar("EventT", bound=JournalEvent)


def _t_holders(sample: JsonObject | None) -> list[JsonObject]:
    """The sample itself and, for a dual_loop pose record, its `observations`."""
    if not sample:
        return []
    nested = sample.get("observations") or ()
    return [sample, *(item for item in nested if isinstance(item, dict))]


def sample_times(sample: JsonObject | None) -> list[float]:
    """The `t` values (s) of one journaled sample (dual_loop: of its observations)."""
    return [float(item["t"]) for item in _t_holders(sample)
            if isinstance(item.get("t"), int | float)]


def shift_sample_t(sample: JsonObject, dt: float) -> JsonObject:
    """A copy of a journaled sample (its JSON form) with every `t` moved by dt (s)."""
    def moved(item: JsonObject) -> JsonObject:
        out = dict(item)
        if isinstance(out.get("t"), int | float):
            out["t"] = float(out["t"]) + dt
        return out

    out = moved(sample)
    if isinstance(sample.get("observations"), list):
        out["observations"] = [moved(item) if isinstance(item, dict) else item
                               for item in sample["observations"]]
    return out


_OFFSET_FIELDS = {
    "push": ("previous_offsets", "new_offsets"),
    "push_intent": ("previous_offsets", "new_offsets"),
    "verify_start": ("offsets", "pushed_delta"),
    "verify": ("offsets",),
    "result": ("offsets",),
    "rollback": ("offsets",),
}


def _numbers(value: Any) -> bool:
    return isinstance(value, list) and all(
        isinstance(v, int | float) and not isinstance(v, bool) for v in value)


def _event_problem(obj: JsonObject) -> str:
    """Why a journaled event cannot be used ("" if it can): the events resume reads must
    carry their offsets as lists of numbers (and a verify round its integer indices)."""
    kind = obj.get("event")
    if not isinstance(kind, str):
        return f"event {kind!r} is not a name"
    for name in _OFFSET_FIELDS.get(kind, ()):
        if not _numbers(obj.get(name)):
            return f"{kind} event: {name} is not a list of numbers"
    if kind == "verify_start" and not all(
            isinstance(obj.get(k), int) and not isinstance(obj.get(k), bool)
            for k in ("round", "first")):
        return "verify_start event: round and first must be integers"
    return ""


class Journal:
    """The journal of one run folder (see the module docstring)."""

    def __init__(self, run_dir: str | Path) -> None:
        self.run_dir = Path(run_dir)
        self.run_path = self.run_dir / RUN_FILE
        self.journal_path = self.run_dir / JOURNAL_FILE
        self._samples: dict[tuple[str, int], SampleRecord] = {}
        # per non-sample line: its typed event (None: a kind this version does not write)
        # and the line as written (outcome.py replays those)
        self._events: list[tuple[JournalEvent | None, JsonObject]] = []
        self._loaded = False

    # ------------------------------------------------------------------ header

    @property
    def exists(self) -> bool:
        """True if the folder holds a run header."""
        return self.run_path.is_file()

    def read_header(self) -> JsonObject:
        """The run header; InputError naming the folder if it is missing or broken."""
        try:
            data = json.loads(self.run_path.read_text(encoding="utf-8"))
        except FileNotFoundError:
            raise InputError(f"{self.run_dir}: not a calibration run folder "
                             f"(no {RUN_FILE})") from None
        except (OSError, ValueError) as exc:
            raise InputError(f"{self.run_path}: cannot read ({exc})") from None
        if not isinstance(data, dict) or data.get("format") != RUN_FORMAT:
            raise InputError(f"{self.run_path}: not a {RUN_FORMAT} header")
        return data

    def write_header(self, header: JsonObject) -> None:
        """Write (or rewrite) the run header atomically."""
        write_json_atomic(self.run_path, {"format": RUN_FORMAT, **header})

    # ------------------------------------------------------------------ records

    def _lines(self) -> Iterator[tuple[int, int, bool, JsonObject | None]]:
        """(line number, byte offset where the line starts, is last line, parsed object or
        None if unreadable) per line."""
        try:
            data = self.journal_path.read_bytes()
        except FileNotFoundError:
            return
        lines = data.splitlines(keepends=True)
        offset = 0
        for number, raw in enumerate(lines, start=1):
            obj: Any = None
            if raw.endswith(b"\n"):
                try:
                    obj = json.loads(raw)
                except (ValueError, RecursionError):
                    obj = None
            yield number, offset, number == len(lines), obj if isinstance(obj, dict) else None
            offset += len(raw)

    def load(self) -> None:
        """Read the journal. A torn LAST line (cut mid-write) is removed; a broken line
        before the end is an InputError (the journal is not silently shortened)."""
        self._samples.clear()
        self._events.clear()
        for number, start, last, obj in self._lines():
            if obj is None:
                if not last:
                    raise InputError(f"{self.journal_path}: line {number} is not a JSON "
                                     "object; repair or remove it to resume")
                with open(self.journal_path, "r+b") as handle:  # drop the torn tail
                    handle.truncate(start)
                    handle.flush()
                    os.fsync(handle.fileno())
                break
            if obj.get("event") == "sample":
                try:
                    record = SampleRecord.from_dict(obj)
                except ValueError as exc:
                    raise InputError(f"{self.journal_path}: line {number}: not a sample "
                                     f"record ({exc}); repair or remove it to resume") from None
                key = (record.phase, record.index)
                if key not in self._samples or not self._samples[key].ok:
                    self._samples[key] = record  # a skipped pose measured again later
            else:
                problem = _event_problem(obj)
                try:
                    event = None if problem else event_from_json(obj)
                except (KeyError, TypeError, ValueError) as exc:
                    problem = f"{obj['event']} event: {exc!r}"
                if problem:
                    raise InputError(f"{self.journal_path}: line {number}: {problem}; "
                                     "repair or remove it to resume")
                self._events.append((event, obj))
        self._loaded = True

    def _ensure_loaded(self) -> None:
        if not self._loaded:
            self.load()

    def _append(self, obj: JsonObject) -> None:
        self.run_dir.mkdir(parents=True, exist_ok=True)
        line = json.dumps(obj, allow_nan=False, separators=(",", ":")) + "\n"
        with open(self.journal_path, "a", encoding="utf-8") as handle:
            handle.write(line)
            handle.flush()
            os.fsync(handle.fileno())

    def record(self, record: SampleRecord) -> bool:
        """Append a sample record; False (nothing written) if that pose is already measured.
        A pose journaled as skipped may be recorded again (measured again on a resume):
        the later record replaces it."""
        self._ensure_loaded()
        key = (record.phase, record.index)
        if key in self._samples and self._samples[key].ok:
            return False
        self._append(record.to_dict())
        self._samples[key] = record
        return True

    def append(self, event: JournalEvent) -> None:
        """Append another event (journal_events.py: `Pushed`, `Note`, ...)."""
        self._add(event, {"event": event.kind, **event.to_json()})

    def event(self, kind: str, **fields: Any) -> None:
        """Append an event line given as its JSON fields (the line codec: an older
        journal's line, a test's input); the run appends typed events (`append`)."""
        line = {"event": kind, **fields}
        self._add(event_from_json(line), line)

    def _add(self, event: JournalEvent | None, line: JsonObject) -> None:
        self._ensure_loaded()
        self._append(line)
        self._events.append((event, line))

    def get(self, phase: str, index: int) -> SampleRecord | None:
        """The record of pose (phase, index), or None."""
        self._ensure_loaded()
        return self._samples.get((phase, index))

    def has(self, phase: str, index: int) -> bool:
        """True if pose (phase, index) is journaled (measured or skipped)."""
        self._ensure_loaded()
        return (phase, index) in self._samples

    def records(self, phase: str) -> list[SampleRecord]:
        """The records of a phase, by pose index."""
        self._ensure_loaded()
        return sorted((r for (p, _), r in self._samples.items() if p == phase),
                      key=lambda r: r.index)

    @overload
    def events(self, kind: type[EventT]) -> list[EventT]: ...
    @overload
    def events(self, kind: str) -> list[JsonObject]: ...

    def events(self, kind: type[EventT] | str) -> list[EventT] | list[JsonObject]:
        """The non-sample events of one type, in order (of one kind name: their lines as
        written)."""
        self._ensure_loaded()
        if isinstance(kind, str):
            return self.timeline(kind)
        return [e for e, _ in self._events if isinstance(e, kind)]

    def last(self, kind: type[EventT]) -> EventT | None:
        """The last event of one kind (None if there is none)."""
        found = self.events(kind)
        return found[-1] if found else None

    def timeline(self, *kinds: str) -> list[JsonObject]:
        """The lines of the non-sample events whose kind is one of `kinds`, as written, in
        journal order (what happened to the controller: push, verify, rollback, ...; read
        by outcome.py's replay)."""
        self._ensure_loaded()
        return [line for _, line in self._events if line.get("event") in kinds]

    @overload
    def last_event(self, *kinds: type[JournalEvent]) -> JournalEvent | None: ...
    @overload
    def last_event(self, *kinds: str) -> JsonObject | None: ...

    def last_event(self, *kinds: type[JournalEvent] | str) -> JournalEvent | JsonObject | None:
        """The last non-sample event of one of the types `kinds` (None if there is none):
        e.g. `last_event(PushIntent, Pushed)` tells an intent whose result is missing.
        Given kind names: the last such line as written."""
        self._ensure_loaded()
        types = tuple(k for k in kinds if not isinstance(k, str))
        for event, line in reversed(self._events):
            if types and isinstance(event, types):
                return event
            if line.get("event") in kinds:
                return line
        return None

    def last_position(self, *kinds: type[JournalEvent]) -> int:
        """The position (among the non-sample events, in journal order) of the last event
        whose kind is one of `kinds`; -1 if there is none. Tells which of two events came
        later, e.g. a `verify_start` before or after the last `push`."""
        self._ensure_loaded()
        for position in range(len(self._events) - 1, -1, -1):
            if isinstance(self._events[position][0], kinds):
                return position
        return -1

    def last_sample_t(self) -> float | None:
        """The largest `t` (s) among the journaled samples (None if no sample has one)."""
        self._ensure_loaded()
        times = [t for record in self._samples.values() for t in sample_times(record.sample)]
        return max(times) if times else None

    def last_end(self) -> tuple[str, list[float]] | None:
        """The phase ("fit"/"verify") of the last journaled pose and where the robot was
        after it, commanded (reported frame of the offsets it was measured under); None if
        none."""
        self._ensure_loaded()
        last: tuple[str, list[float]] | None = None
        for _, _, _, obj in self._lines():
            if obj and obj.get("event") == "sample" and obj.get("q_end") is not None:
                last = (str(obj.get("phase")), obj["q_end"])
        return last
