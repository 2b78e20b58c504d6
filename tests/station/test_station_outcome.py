"""The station tells the PLC what the run did to the ROBOT (the run's outcome), never a
model check: a refused push is FAIL with result code 5; a cell whose target frame is
estimated leaves J1 and J6 not calibrated: FAIL, code 7, and the joint bitmasks say which;
a PLC abort after the push lets the verification finish, so controller, archive and
registers agree; a station restarted before ACKNOWLEDGE serves the last result again.
Real station process, real pymodbus client, simulated controller, real SQLite archive."""

from __future__ import annotations

import json
import subprocess
import time
from pathlib import Path
from typing import Any

import numpy as np

from hostpc.archive import open_archive
from hostpc.archive.rows import ArchivedRun
from hostpc.station import registers as reg
from tests.station.conftest import REPO, StationFactory, hostpc_command
from tests.station.plc_client import Plc, run_one

FINISHED = {reg.State.PASS, reg.State.FAIL, reg.State.ERROR}


def _archived(config: dict[str, Any]) -> list[ArchivedRun]:
    with open_archive(str(config["db"])) as archive:
        return archive.runs()


def test_a_refused_push_is_fail_code_5_and_served_again_after_a_restart(
        make_station: StationFactory) -> None:
    process, config = make_station(calibrate_args=["--max-correction", "0.01"])
    plc = Plc(config["modbus"]["port"])
    try:
        plc.start("SN-REFUSED")
        values = plc.wait_state(FINISHED, 300)
    finally:
        plc.close()
    log = process.log.read_text()
    assert reg.State(values[reg.STATE]) == reg.State.FAIL, log[-2000:]
    assert values[reg.RESULT_CODE] == 5
    assert values[reg.OUTCOME_FLAGS] == reg.FLAG_REFUSED  # not pushed, not verified
    assert values[reg.JOINTS_CALIBRATED] == 0b011111  # J1-J5 from data (J6: tool estimated)
    assert values[reg.JOINTS_NOT_CALIBRATED] == 0b100000
    assert values[reg.JOINTS_REQUIRED_MISSING] == 0b100000  # the station requires all
    runs = _archived(config)
    assert [r.verdict for r in runs] == ["REFUSED"]
    run_dir = Path(runs[0].run_dir)
    outcome = json.loads((run_dir / "result.json").read_text())["outcome"]
    assert outcome["verdict"] == "REFUSED" and outcome["controller"] == "offsets unchanged"

    # restart before ACKNOWLEDGE: the same result registers again
    assert process.stop() == 0
    process.start()
    plc = Plc(config["modbus"]["port"])
    try:
        again = plc.read()
        assert again[reg.STATE:reg.RESULT_CODE + 1] == values[reg.STATE:reg.RESULT_CODE + 1]
        assert again[reg.ARCHIVE_ID:reg.OUTCOME_FLAGS + 1] == \
            values[reg.ARCHIVE_ID:reg.OUTCOME_FLAGS + 1]
        plc.command(reg.Command.ACKNOWLEDGE)
        plc.wait_state({reg.State.IDLE}, 10)
    finally:
        plc.close()
    assert process.stop() == 0
    process.start()  # acknowledged: not served again
    plc = Plc(config["modbus"]["port"])
    try:
        assert reg.State(plc.read()[reg.STATE]) == reg.State.IDLE
    finally:
        plc.close()


def test_target_estimated_is_fail_code_7_with_the_joint_bitmasks(
        make_station: StationFactory) -> None:
    process, config = make_station(known="none")
    values = run_one(config["modbus"]["port"], "SN-NOREF")
    assert reg.State(values[reg.STATE]) == reg.State.FAIL, process.log.read_text()[-2000:]
    assert values[reg.RESULT_CODE] == 7
    assert values[reg.JOINTS_CALIBRATED] == 0b011110  # J2-J5 pushed and verified
    assert values[reg.JOINTS_NOT_CALIBRATED] == 0b100001  # J1 (target), J6 (tool)
    assert values[reg.JOINTS_REQUIRED_MISSING] == 0b100001
    assert values[reg.OUTCOME_FLAGS] == reg.FLAG_PUSHED | reg.FLAG_VERIFIED
    (run,) = _archived(config)
    assert run.verdict == "JOINTS_MISSING"
    # the station's next step: the reference goes into its config (a hand-run's next
    # command would not reach the station's runs)
    reference = f"{run.run_dir.rstrip('/')}.cell_ref.json"
    assert f'put "--reference", "{reference}", "--rig", "{reference[:-5]}.rig.json" in ' \
        "calibrate_args of " in str(run.reason)
    # never a reference of this run's zeros: every later robot would inherit them
    assert f"hostpc reference record --run THAT_RUN --out {reference}" in str(run.reason)
    assert "known good" in str(run.reason)

    # the step done with this run all the same (the simulated robot's J1/J6 zeros are off):
    # the next robot has every joint set (no loop), and the PLC is told that J1 and J6
    # are as this run found them, not measured
    record = subprocess.run(hostpc_command("reference", "record", "--run", run.run_dir,
                                           "--out", reference),
                            cwd=REPO, capture_output=True, text=True, timeout=300)
    assert record.returncode == 0, record.stderr
    assert process.stop() == 0
    process, config = make_station(known="none", calibrate_args=[
        "--reference", reference, "--rig", f"{reference[:-5]}.rig.json"])
    plc = Plc(config["modbus"]["port"])
    try:
        plc.command(reg.Command.ACKNOWLEDGE)  # SN-NOREF's result, served again
        plc.wait_state({reg.State.IDLE}, 10)
        values = plc.run("SN-NOREF-2")
    finally:
        plc.close()
    assert reg.State(values[reg.STATE]) == reg.State.PASS, process.log.read_text()[-2000:]
    assert values[reg.JOINTS_CALIBRATED] == 0b111111
    assert values[reg.JOINTS_AS_FOUND] == 0b100001  # J1, J6: restored to SN-NOREF's zeros


def test_an_abort_after_the_push_lets_verification_finish(make_station: StationFactory) -> None:
    process, config = make_station(verify_poses=8, calibrate_args=["--time-scale", "0.3"],
                                   require_joints="1,2,3,4,5")  # J6: tool estimated
    plc = Plc(config["modbus"]["port"])
    runs_dir = Path(config["runs_dir"])
    try:
        plc.start("SN-ABORT")
        deadline = time.monotonic() + 300
        journal = None
        while time.monotonic() < deadline:
            found = [p for p in runs_dir.glob("SN-ABORT-*/journal.jsonl")
                     if '"event":"push"' in p.read_text()]
            if found:
                journal = found[0]
                break
            time.sleep(0.02)
        assert journal is not None, process.log.read_text()[-2000:]
        assert '"event":"result"' not in journal.read_text()  # still verifying
        plc.command(reg.Command.START)  # not while running: cleared, and said so
        deadline = time.monotonic() + 5
        while plc.read()[reg.COMMAND_IGNORED] != reg.Command.START:
            assert time.monotonic() < deadline, "a START while running looks taken"
            time.sleep(0.05)
        assert plc.read()[reg.COMMAND] == 0
        plc.command(reg.Command.ABORT)
        values = plc.wait_state(FINISHED, 300)
    finally:
        plc.close()
    log = process.log.read_text()
    assert "PLC abort deferred" in log, log[-2000:]
    assert reg.State(values[reg.STATE]) == reg.State.PASS and values[reg.RESULT_CODE] == 0
    assert values[reg.OUTCOME_FLAGS] == reg.FLAG_PUSHED | reg.FLAG_VERIFIED
    events = [json.loads(line) for line in journal.read_text().splitlines()]
    push = next(e for e in events if e["event"] == "push")
    result = next(e for e in events if e["event"] == "result")
    # what the controller held at the end is what was pushed and verified
    np.testing.assert_allclose(result["offsets"], push["new_offsets"], rtol=0, atol=1e-12)
    outcome = json.loads((journal.parent / "result.json").read_text())["outcome"]
    assert outcome["controller"] == "new offsets, verified"
    assert [r.verdict for r in _archived(config)] == ["PASS"]
    assert not (runs_dir / "current.json").exists()
