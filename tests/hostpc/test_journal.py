"""The run journal: append-only, keyed by (phase, index), survives torn writes."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from hostpc.calibrate.journal import Journal, sample_times, shift_sample_t
from hostpc.errors import InputError
from hostpc.methods.base import SampleRecord


def ok(index: int, phase: str = "fit") -> SampleRecord:
    return SampleRecord(phase, index, True, sample={"q": [0.1 * index] * 6, "p": [0, 0, 0.4],
                                                    "sigma": 1e-5},
                        q_end=[0.1 * index] * 6)  # type: ignore[arg-type]


def test_records_persist_and_are_never_replaced(tmp_path: Path) -> None:
    journal = Journal(tmp_path)
    assert journal.record(ok(0)) and journal.record(ok(1))
    assert journal.record(SampleRecord("fit", 2, False, reason="target rejected: no disk",
                                       q_end=[0.3] * 6))
    assert not journal.record(ok(1))  # a pose already journaled is not measured twice
    assert journal.record(ok(0, "verify"))
    again = Journal(tmp_path)  # a resume reads it back
    assert [r.index for r in again.records("fit")] == [0, 1, 2]
    assert [r.ok for r in again.records("fit")] == [True, True, False]
    assert again.records("fit")[2].reason == "target rejected: no disk"
    assert again.has("verify", 0) and not again.has("verify", 1)
    assert again.last_end() == ("verify", [0.0] * 6)  # the verify pose 0 came last
    assert len((tmp_path / "journal.jsonl").read_text().splitlines()) == 4


def test_events_and_header(tmp_path: Path) -> None:
    journal = Journal(tmp_path)
    assert not journal.exists
    with pytest.raises(InputError, match="not a calibration run folder"):
        journal.read_header()
    journal.write_header({"settings": {"method": "stereo_target"}, "seed": 4})
    journal.event("push", rollback_id="rb-1", previous_offsets=[0.0], new_offsets=[0.1])
    again = Journal(tmp_path)
    assert again.read_header()["seed"] == 4
    assert again.events("push")[0]["rollback_id"] == "rb-1"
    (tmp_path / "run.json").write_text("{}")
    with pytest.raises(InputError, match="zerocal-run/1"):
        Journal(tmp_path).read_header()


def test_torn_last_line_is_dropped_and_appending_continues(tmp_path: Path) -> None:
    journal = Journal(tmp_path)
    journal.record(ok(0))
    journal.record(ok(1))
    path = tmp_path / "journal.jsonl"
    with open(path, "a") as handle:  # a power cut in the middle of the third line
        handle.write('{"event": "sample", "phase": "fit", "ind')
    again = Journal(tmp_path)
    assert [r.index for r in again.records("fit")] == [0, 1]
    assert again.record(ok(2))
    lines = path.read_text().splitlines()
    assert [json.loads(line)["index"] for line in lines] == [0, 1, 2]


def test_broken_line_before_the_end_is_an_error_not_a_silent_cut(tmp_path: Path) -> None:
    journal = Journal(tmp_path)
    journal.record(ok(0))
    path = tmp_path / "journal.jsonl"
    path.write_text("garbage\n" + path.read_text())
    with pytest.raises(InputError, match="line 1"):
        Journal(tmp_path).load()
    assert path.read_text().startswith("garbage\n")  # nothing was truncated


def test_last_event_tells_an_intent_without_its_result(tmp_path: Path) -> None:
    journal = Journal(tmp_path)
    journal.event("push_intent", previous_offsets=[0.0], new_offsets=[0.1], time="t0")
    journal.event("note", text="something else")
    again = Journal(tmp_path)
    last = again.last_event("push_intent", "push")
    assert last is not None and last["event"] == "push_intent"
    again.event("push", rollback_id="rb-1", previous_offsets=[0.0], new_offsets=[0.1])
    assert Journal(tmp_path).last_event("push_intent", "push")["event"] == "push"  # type: ignore[index]
    assert Journal(tmp_path).last_event("missing") is None


def test_sample_times_and_shift_reach_nested_observations(tmp_path: Path) -> None:
    journal = Journal(tmp_path)
    assert journal.last_sample_t() is None
    journal.record(SampleRecord("fit", 0, True, sample={"q": [0.0], "t": 2.5}))
    pose = {"observations": [{"chain": "left", "t": 4.0}, {"chain": "right", "t": 4.5}]}
    journal.record(SampleRecord("fit", 1, True, sample=pose))
    assert Journal(tmp_path).last_sample_t() == 4.5
    assert sample_times(pose) == [4.0, 4.5]
    moved = shift_sample_t(pose, 10.0)
    assert sample_times(moved) == [14.0, 14.5] and sample_times(pose) == [4.0, 4.5]


def test_a_skipped_pose_may_be_measured_again_a_measured_one_not(tmp_path) -> None:  # type: ignore[no-untyped-def]
    from hostpc.calibrate.journal import Journal
    from hostpc.methods.base import SampleRecord

    journal = Journal(tmp_path)
    assert journal.record(SampleRecord("fit", 0, False, reason="move stopped: aborted"))
    assert journal.record(SampleRecord("fit", 0, True, sample={"q": [0.0]}))
    assert not journal.record(SampleRecord("fit", 0, True, sample={"q": [1.0]}))
    again = Journal(tmp_path)
    again.load()
    (record,) = again.records("fit")
    assert record.ok and record.sample == {"q": [0.0]}
