"""The journal's typed events (hostpc.calibrate.journal_events): a line read back and
written again is the same bytes, an older line still loads, and the offline push ledger's
entries round-trip the same way."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from hostpc.calibrate.journal import Journal
from hostpc.calibrate.journal_events import (
    EVENT_TYPES,
    MorePoses,
    Note,
    Pushed,
    PushIntent,
    PushRefused,
    Rollback,
    RunFinished,
    Verified,
    VerifyStart,
    event_from_json,
)
from hostpc.calibrate.offline_push import LedgerEntry, already_pushed, record_push
from hostpc.calibrate.resume import verify_round
from hostpc.errors import InputError

OFFSETS = "[-0.0029366768741019684,0.0019590876763978986,0.00013021129288329707,0.0]"
LINES = [  # as `hostpc calibrate` writes them (a refused run, resumed with --force)
    '{"event":"robot_time","phase":"rig","seconds":2.0000000000000004,"clock":"controller"}',
    '{"event":"push_refused","reason":"joint 4 correction -0.3435 deg exceeds the limit of '
    '0.05 deg","at":"2026-11-28T09:08:43.010+00:00"}',
    '{"event":"push_refused","reason":"offset_limit","by":"controller",'
    '"at":"2026-11-28T09:08:43.010+00:00"}',
    '{"event":"verify_start","round":0,"first":0,"offsets":[0.0,0.0],"pushed_delta":[0.0,0.0]}',
    '{"event":"verify","round":0,"verdict":"PASS","at":"2026-11-28T09:08:43.660+00:00",'
    '"statistic":2.714397912706663,"dof":12,"p_value":0.9972464476393246,"offsets":[0.0,0.0]}',
    '{"event":"verify","round":1,"verdict":"FAIL","at":"t","statistic":null,"dof":0,'
    '"p_value":null,"offsets":[0.1]}',
    '{"event":"verify_lost","round":2}',
    '{"event":"result","exit_code":5,"push":"refused","verdict":null,"outcome":"REFUSED",'
    '"at":"2026-11-28T09:08:43.680+00:00","offsets":[0.0,0.0]}',
    '{"event":"note","text":"settings changed on resume","overrides":{"force":true}}',
    '{"event":"note","text":"reference loaded","reference":"ref.json",'
    '"recorded":"2026-01-02T03:04:05+00:00"}',
    '{"event":"note","text":"known frames changed on resume","known":["tool","target"]}',
    '{"event":"note","text":"controller clock restarted","last_t":12.5,"time_origin":-3.25}',
    '{"event":"note","text":"sample t went backwards on resume","t_shift":1.5}',
    '{"event":"resumed","at":"2026-11-28T09:08:49.644+00:00"}',
    '{"event":"more_poses","reason":"chi2/dof 4.1 above its band","n":20}',
    '{"event":"push_intent","previous_offsets":[0.0,0.0,0.0,0.0],"new_offsets":' + OFFSETS
    + ',"pushed":[true,true,true,false],"time":"2026-11-28T09:08:50.208+00:00"}',
    '{"event":"push_written","rollback_id":"rb-1","time":"2026-11-28T09:08:50.230+00:00"}',
    '{"event":"push","rollback_id":"rb-1","previous_offsets":[0.0,0.0,0.0,0.0],'
    '"new_offsets":' + OFFSETS + ',"pushed":[true,true,true,false],'
    '"time":"2026-11-28T09:08:50.250+00:00"}',
    '{"event":"push","rollback_id":null,"previous_offsets":[0.0],"new_offsets":[0.1],'
    '"pushed":[true],"time":"t0","recovered":true}',
    '{"event":"rollback","how":"rollback_id","controller":"127.0.0.1:5555",'
    '"offsets":[0.0,0.0],"time":"2026-11-28T10:00:00+00:00"}',
    '{"event":"stage","number":1,"first":1000,"at":"t","estimate":[0.0,3.14,0.0]}',
]


def _written(line: str) -> str:
    """The line read into its typed event and written back as the journal writes it."""
    event = event_from_json(json.loads(line))
    assert event is not None
    return json.dumps({"event": event.kind, **event.to_json()}, allow_nan=False,
                      separators=(",", ":"))


@pytest.mark.parametrize("line", LINES)
def test_a_journal_line_read_and_written_again_is_the_same_bytes(line: str) -> None:
    assert _written(line) == line


def test_every_event_kind_has_a_round_trip_case() -> None:
    kinds = {json.loads(line)["event"] for line in LINES}
    assert kinds == {kind.kind for kind in EVENT_TYPES}


def test_appended_events_are_the_lines_and_read_back_by_type(tmp_path: Path) -> None:
    journal = Journal(tmp_path)
    for line in LINES:
        event = event_from_json(json.loads(line))
        assert event is not None
        journal.append(event)
    written = (tmp_path / "journal.jsonl").read_text(encoding="utf-8").splitlines()
    assert written == LINES
    again = Journal(tmp_path)
    pushes = again.events(Pushed)
    assert [p.record.rollback_id for p in pushes] == ["rb-1", None]
    assert pushes[-1].recovered and not pushes[0].recovered
    np.testing.assert_array_equal(pushes[0].record.new, json.loads(OFFSETS))
    assert isinstance(again.last_event(PushIntent, Pushed), Pushed)
    assert isinstance(again.last_event(Pushed, Rollback), Rollback)
    assert again.last(MorePoses) == MorePoses("chi2/dof 4.1 above its band", 20)
    assert [r.by for r in again.events(PushRefused)] == [None, "controller"]
    final = again.last(RunFinished)
    assert final is not None and final.verdict is None and final.exit_code == 5
    assert again.last_position(VerifyStart) < again.last_position(Pushed)
    assert [line["event"] for line in again.timeline("push", "rollback")] == [
        "push", "push", "rollback"]


def test_an_older_journals_lines_still_load(tmp_path: Path) -> None:
    """Lines without the fields a later version added (a push without `pushed` / `time`,
    a verify without dof or p-value, a note with facts this version does not know) load;
    what the run reads of them takes its default."""
    old = [
        {"event": "push", "rollback_id": "rb-1", "previous_offsets": [0.0],
         "new_offsets": [0.1]},
        {"event": "verify", "round": 0, "verdict": "PASS", "offsets": [0.1]},
        {"event": "note", "text": "something", "detail": {"a": 1}},
        {"event": "future_kind", "anything": [1, 2]},
        {"event": "verify_start", "round": 1, "first": 3, "offsets": [0.1],
         "pushed_delta": [0.1]},
    ]
    (tmp_path / "journal.jsonl").write_text(
        "".join(json.dumps(line) + "\n" for line in old), encoding="utf-8")
    journal = Journal(tmp_path)
    (push,) = journal.events(Pushed)
    assert push.record.pushed == () and push.record.time == "" and not push.recovered
    (verified,) = journal.events(Verified)
    assert verified.dof == 0 and verified.p_value is None and verified.at == ""
    assert journal.events(Note) == [Note("something")]
    assert [line["event"] for line in journal.events("future_kind")] == ["future_kind"]
    assert verify_round(journal, np.array([0.1]), np.array([0.1]), 3) == (1, 3)


def test_a_broken_stage_line_is_refused_with_its_line_number(tmp_path: Path) -> None:
    (tmp_path / "journal.jsonl").write_text(
        '{"event":"note","text":"x"}\n{"event":"stage","first":3,"estimate":[0.0]}\n',
        encoding="utf-8")
    with pytest.raises(InputError, match="line 2: stage event"):
        Journal(tmp_path).load()


def test_ledger_entries_round_trip_and_tell_a_push_already_made(tmp_path: Path) -> None:
    fit = tmp_path / "FIT.json"
    line = ('{"controller": "127.0.0.1:5555", "run_dir": "/runs/push-1", "time": '
            '"2026-11-28T10:00:00+00:00", "before": [0.0, 0.0], "after": [0.001, -0.002]}')
    entry = LedgerEntry.from_json(json.loads(line))
    assert json.dumps(entry.to_json()) == line
    record_push(fit, entry)
    assert (tmp_path / "FIT.json.pushes.jsonl").read_text(encoding="utf-8") == line + "\n"
    assert already_pushed(fit, np.array([0.001, -0.002])) == entry
    assert already_pushed(fit, np.array([0.0, 0.0])) is None
