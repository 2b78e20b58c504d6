"""What a resume reads from the journal: verification rounds (a verdict only uses poses
measured under the offsets it judges; a lost round is measured again) and the push state
(pushed / rolled back / lost)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from hostpc.calibrate.journal import Journal
from hostpc.calibrate.resume import PushLost, push_state, verify_round
from hostpc.methods.base import NullProgress, SampleRecord

K = 3
OLD = np.zeros(6)
NEW = np.full(6, 1e-3)


def test_verify_rounds_follow_the_controller_offsets(tmp_path: Path) -> None:
    journal = Journal(tmp_path)
    assert verify_round(journal, OLD, np.zeros(6), K) == (0, 0)  # a model check, say
    journal.record(SampleRecord("verify", 0, True, sample={"q": [0.0]}))
    assert verify_round(journal, OLD, np.zeros(6), K) == (0, 0)  # same offsets: continue
    # after a push: a new round, never the poses measured before it
    assert verify_round(journal, NEW, NEW - OLD, K) == (1, K)
    for index in range(K, 2 * K):  # an abort storm skips every pose of the round
        journal.record(SampleRecord("verify", index, False, reason="move stopped: aborted"))
    assert verify_round(journal, NEW, NEW - OLD, K) == (2, 2 * K)  # lost: measured again
    starts = Journal(tmp_path).events("verify_start")
    assert [e["round"] for e in starts] == [0, 1, 2]


def test_push_state_tells_pushed_rolled_back_and_lost(tmp_path: Path) -> None:
    journal = Journal(tmp_path)
    progress = NullProgress()
    zero = np.zeros(6)
    assert push_state(journal, tmp_path, progress, OLD, False, zero) is None  # no push
    journal.event("push", rollback_id="rb-1", previous_offsets=OLD.tolist(),
                  new_offsets=NEW.tolist(), pushed=[True] * 6, time="t")
    status, delta = push_state(journal, tmp_path, progress, NEW, False, zero)  # type: ignore[misc]
    assert status == "pushed" and np.allclose(delta, NEW - OLD)
    with pytest.raises(PushLost, match="--push"):
        push_state(journal, tmp_path, progress, OLD, False, zero)  # restarted controller
    assert push_state(journal, tmp_path, progress, OLD, True, zero) is None  # --push: again
    journal.event("rollback", how="rollback_id", controller="c", offsets=OLD.tolist(),
                  time="t")
    assert push_state(journal, tmp_path, progress, OLD, False, zero)[0] == "rolled_back"  # type: ignore[index]


def test_a_push_again_of_the_same_offsets_starts_a_new_verify_round(tmp_path: Path) -> None:
    """A restarted controller lost the push; `--resume --push` writes the same offsets
    again: the verdict must not reuse the poses measured after the first push."""
    journal = Journal(tmp_path)
    push = {"rollback_id": "rb-1", "previous_offsets": OLD.tolist(),
            "new_offsets": NEW.tolist(), "pushed": [True] * 6, "time": "t"}
    journal.event("push", **push)
    assert verify_round(journal, NEW, NEW - OLD, K) == (0, 0)
    for index in range(K - 1):  # measured, then the host was killed
        journal.record(SampleRecord("verify", index, True, sample={"q": [0.0]}))
    assert verify_round(journal, NEW, NEW - OLD, K) == (0, 0)  # no new push: continue
    journal.event("push", **push)  # pushed again (same offsets, same delta)
    assert verify_round(Journal(tmp_path), NEW, NEW - OLD, K) == (1, K)


def test_a_lost_verification_sends_to_a_resume_only_when_measuring_again_can_help(
        tmp_path: Path) -> None:
    """An abort storm passes: resume. Poses lost to what the robot found there (a touch
    that misses the sphere) are lost again by a resume: rollback the push, or diagnose."""
    from hostpc.calibrate.resume import verify_lost_line

    storm = [SampleRecord("verify", i, False, reason="move stopped: aborted") for i in range(K)]
    line = verify_lost_line(storm, K, True, tmp_path)
    assert line.endswith(f"measure them again with: hostpc calibrate --resume {tmp_path}")
    missed = [SampleRecord("verify", i, False, reason="no probe contact before the end of "
                           "travel (no_contact)") for i in range(K)]
    line = verify_lost_line(missed, K, True, tmp_path)
    assert "the pushed offsets stay in the controller" in line
    assert line.endswith(f"hostpc rollback --run {tmp_path}") and "--resume" not in line
    line = verify_lost_line(missed, K, False, tmp_path)
    assert "nothing was pushed" in line
    assert line.endswith(f"hostpc diagnose {tmp_path}/dataset.json") and "--resume" not in line
