"""Where a resume finds the robot (resume.resume_pose): the controller's reading, in the
frame of the offsets the last journaled pose was measured under (the controller reports
encoder + offset), or that pose when the reading agrees with it."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from hostpc.calibrate.journal import Journal
from hostpc.calibrate.resume import resume_pose
from hostpc.methods.base import NullProgress, SampleRecord

INITIAL = np.zeros(6)
PUSHED = np.array([0.0, 0.2, -0.1, 0.05, 0.0, 0.0])  # rad: a staged run's large push
END = [0.3, -1.2, 1.4, -0.2, 1.5, 0.1]


def _journal(tmp_path: Path, phase: str, pushed: bool) -> Journal:
    journal = Journal(tmp_path)
    journal.record(SampleRecord("fit", 0, False, reason="missed", q_end=END))
    if pushed:
        journal.event("push", rollback_id="rb-1", previous_offsets=INITIAL.tolist(),
                      new_offsets=PUSHED.tolist())
    if phase == "verify":
        journal.record(SampleRecord("verify", 0, False, reason="missed", q_end=END))
    return Journal(tmp_path)


def test_not_moved_is_the_journaled_pose_in_every_frame(tmp_path: Path) -> None:
    # a fit pose then a push: the same place reads END + pushed; the journal's frame is
    # the initial offsets' (the staging adds the push once, for the verification)
    journal = _journal(tmp_path / "a", "fit", pushed=True)
    q = resume_pose(journal, np.add(END, PUSHED), INITIAL + PUSHED, INITIAL, NullProgress())
    assert q.tolist() == END
    # a verification pose, measured under the pushed offsets: read as it is
    journal = _journal(tmp_path / "b", "verify", pushed=True)
    q = resume_pose(journal, np.asarray(END), INITIAL + PUSHED, INITIAL, NullProgress())
    assert q.tolist() == END


def test_moved_is_the_reading_in_the_journals_frame(tmp_path: Path) -> None:
    moved = np.add(END, [0.0, 0.0, 0.0, 0.0, 0.0, 0.3])
    journal = _journal(tmp_path / "a", "fit", pushed=True)
    q = resume_pose(journal, moved + PUSHED, INITIAL + PUSHED, INITIAL, NullProgress())
    assert np.allclose(q, moved, atol=1e-12)
    journal = _journal(tmp_path / "b", "fit", pushed=False)
    assert np.allclose(resume_pose(journal, moved, INITIAL, INITIAL, NullProgress()), moved)
    journal = Journal(tmp_path / "c")  # nothing journaled: the reading
    assert resume_pose(journal, moved, INITIAL, INITIAL, NullProgress()).tolist() == \
        moved.tolist()
