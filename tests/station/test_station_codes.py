"""The station's codes and records from what a run left: a push lost has its own reason
code (not "controller refused"), read from calibrate's own PushLost text; a run stopped
after its push, without a result, is archived as pushed, with the journal's offsets."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from hostpc.archive import record_from_run
from hostpc.calibrate.journal import Journal
from hostpc.calibrate.resume import PushLost, push_state
from hostpc.methods.base import NullProgress
from hostpc.station import registers as reg

OLD = np.zeros(6)
NEW = np.array([1e-3, -2e-3, 0.0, 4e-3, 5e-4, 0.0])
PUSHED = [True, True, False, True, True, False]


def _pushed_journal(run_dir: Path) -> Journal:
    journal = Journal(run_dir)
    journal.event("push", rollback_id="rb-1", previous_offsets=OLD.tolist(),
                  new_offsets=NEW.tolist(), pushed=PUSHED, time="t")
    return journal


def test_a_push_lost_has_its_own_reason_code(tmp_path: Path) -> None:
    journal = _pushed_journal(tmp_path)
    with pytest.raises(PushLost) as lost:  # the controller has its previous offsets again
        push_state(journal, tmp_path, NullProgress(), OLD, False, np.zeros(6))
    reason = str(lost.value)  # calibrate's error line, as the station reads it
    values = reg.outcome_registers(reg.RunOutcome(reg.State.ERROR, 4, reason=reason))
    assert values[reg.REASON_CODE] == reg.Reason.PUSH_LOST
    refused = reg.outcome_registers(reg.RunOutcome(
        reg.State.ERROR, 4, reason="controller refused (estop): emergency stop active"))
    assert refused[reg.REASON_CODE] == reg.Reason.CONTROLLER_REFUSED


def test_a_run_stopped_after_its_push_is_archived_as_pushed(tmp_path: Path) -> None:
    _pushed_journal(tmp_path)  # no result.json: stopped while verifying
    record = record_from_run(tmp_path, serial="SN-1", exit_code=4)
    assert (record.verdict, record.push_status) == ("ERROR", "pushed")
    assert [o.pushed for o in record.offsets] == PUSHED
    for o, old, new in zip(record.offsets, OLD, NEW, strict=True):
        assert o.correction_deg == pytest.approx(math.degrees(new - old), abs=1e-12)
        assert o.new_deg == pytest.approx(math.degrees(new), abs=1e-12)
    assert record.largest_correction_deg == pytest.approx(math.degrees(4e-3), abs=1e-12)
    bits = reg.outcome_bits(record.outcome, record.push_status,
                            [o.joint for o in record.offsets if o.pushed])
    assert bits.outcome_flags == reg.FLAG_PUSHED and bits.joints_pushed == 0b011011
    # a rollback since: nothing the controller holds of this run
    Journal(tmp_path).event("rollback", how="rollback_id", controller="c",
                            offsets=OLD.tolist(), time="t")
    assert record_from_run(tmp_path, serial="SN-1", exit_code=4).push_status == "none"
