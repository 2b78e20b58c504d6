"""What the station tells the PLC is true of the robot, also when a run ends between its
push and its verdict: an estop during the verification leaves pushed offsets nobody
verified (the registers and the archive say pushed, how much, which joints; the next robot
is refused until that run is settled, never silently dropped); a PASS rolled back since
is served as the archive has it now, also after a restart; a START the station does not
take says so in a register. Real `controller-stub serve --port 0` as the cell's
controller, real station process, real pymodbus client, real SQLite archive."""

from __future__ import annotations

import json
import math
import re
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

from hostpc.archive import open_archive
from hostpc.robots.simulator import default_sim_scenario
from hostpc.serving.log_limits import MAX_LINE
from hostpc.station import registers as reg
from tests.station.conftest import REPO, StationFactory, hostpc_command
from tests.station.plc_client import Plc, run_one
from tests.station.test_station import StationProcess

FINISHED = {reg.State.PASS, reg.State.FAIL, reg.State.ERROR}
TOKEN = "station-truths-token"
LISTENING = re.compile(r"listening on (?P<host>[\d.]+):(?P<port>\d+)")


def _world(token: str | None = TOKEN, **faults: int) -> dict[str, Any]:
    """The default simulated cell with its target where the cell says (known: target is
    true), the controller's `token` and `faults`."""
    world = default_sim_scenario()
    world["target"] = {**world["target"], "centre_error": [0.0, 0.0, 0.0]}
    if token is not None:
        world["server"] = {**world.get("server", {}), "token": token}
    if faults:
        world["faults"] = dict(faults)
    return world


StubFactory = Callable[..., str]


@pytest.fixture
def controller(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[StubFactory]:
    """`controller-stub serve --port 0` on a world with the given faults; returns its
    HOST:PORT (its token in the environment, as a station's service unit has it)."""
    monkeypatch.setenv("ZEROCAL_TOKEN", TOKEN)
    started: list[subprocess.Popen[str]] = []

    def serve(**faults: int) -> str:
        scenario = tmp_path / f"world{len(started)}.json"
        scenario.write_text(json.dumps(_world(**faults)))
        process = subprocess.Popen([sys.executable, "-m", "controller_stub", "serve",
                                    "--scenario", str(scenario), "--port", "0"],
                                   cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                   text=True)
        started.append(process)
        assert process.stdout is not None
        match = LISTENING.search(process.stdout.readline())
        assert match, process.stderr.read() if process.stderr else ""
        return f"{match['host']}:{match['port']}"

    yield serve
    for process in started:
        process.terminate()
        process.wait(timeout=10)


@pytest.fixture
def station_on(make_station: StationFactory) -> StationFactory:
    """A station of this module's cell on `robot`: J1-J5 required (J6: tool estimated),
    no resume unless `resume_attempts`, `args` after the rig."""
    def make(robot: str, *args: str, **overrides: Any) -> tuple[StationProcess,
                                                                  dict[str, Any]]:
        return make_station(**{"station": "eol-truth", "robot": robot,
                               "require_joints": "1,2,3,4,5", "resume_attempts": 0,
                               "calibrate_args": list(args), **overrides})
    return make


def _reason(values: list[int]) -> str:
    return reg.decode_text(values[reg.REASON:reg.REASON + reg.REASON_LENGTH])


def _mask(joints: list[int]) -> int:
    return sum(1 << (j - 1) for j in joints)


@pytest.mark.slow
def test_an_estop_after_the_push_is_pushed_not_verified_and_blocks_the_next_robot(
        controller: StubFactory, station_on: StationFactory
        ) -> None:
    process, config = station_on(controller(estop_after_moves=15))  # 12 fit poses, then
    plc = Plc(config["modbus"]["port"])                              # the estop verifying
    runs_dir = Path(config["runs_dir"])
    try:
        values = plc.run("SN-R3")
        log = process.log.read_text()
        assert reg.State(values[reg.STATE]) == reg.State.ERROR, log[-3000:]
        assert values[reg.RESULT_CODE] == 4
        (run_dir,) = runs_dir.glob("SN-R3-*/")
        events = [json.loads(line) for line in (run_dir / "journal.jsonl").read_text()
                  .splitlines()]
        push = next(e for e in events if e["event"] == "push")
        assert not any(e["event"] == "result" for e in events)  # stopped verifying
        moved = [math.degrees(n - o) for n, o in zip(push["new_offsets"],
                                                      push["previous_offsets"], strict=True)]
        pushed = [j for j, p in enumerate(push["pushed"], start=1) if p]
        assert pushed  # the controller holds them: what the registers must say
        assert values[reg.OUTCOME_FLAGS] == reg.FLAG_PUSHED  # pushed, NOT verified
        assert values[reg.JOINTS_PUSHED] == _mask(pushed)
        assert values[reg.JOINTS_CALIBRATED] == 0  # nothing verified
        largest = max(abs(moved[j - 1]) for j in pushed)
        assert reg.decode_int32(values[reg.LARGEST_CORRECTION:reg.LARGEST_CORRECTION + 2]) \
            == round(largest * 1e4)
        with open_archive(str(config["db"]), create=False) as archive:
            (row,) = archive.runs()
        assert (row.verdict, row.push_status) == ("ERROR", "pushed")
        assert [o.joint for o in row.offsets if o.pushed] == pushed
        for o in row.offsets:
            assert o.correction_deg == pytest.approx(moved[o.joint - 1], abs=1e-9)
        assert row.largest_correction_deg == pytest.approx(largest, abs=1e-9)
        # the whole reason with the station's next step, in the log (never cut)
        assert row.reason is not None and "START SN-R3 again" in row.reason
        assert f"hostpc calibrate --resume {run_dir} --db " in row.reason
        assert len(row.reason) > MAX_LINE  # the limit peer-reachable lines are cut to
        assert f"run of SN-R3: ERROR (result code 4, archive id 1): {row.reason}" in log
        assert json.loads((runs_dir / "current.json").read_text())["run_dir"] == \
            str(run_dir)

        # a START before ACKNOWLEDGE is not taken, and the PLC can read so
        assert values[reg.COMMAND_IGNORED] == 0
        plc.start("SN-OTHER")
        time.sleep(0.5)
        values = plc.read()
        assert values[reg.COMMAND] == 0 and values[reg.COMMAND_IGNORED] == reg.Command.START
        assert reg.State(values[reg.STATE]) == reg.State.ERROR
        assert values[reg.RESULT_CODE] == 4  # still SN-R3's result

        # the next robot is refused while SN-R3's push is not verified: never dropped
        plc.command(reg.Command.ACKNOWLEDGE)
        values = plc.wait_state({reg.State.IDLE}, 10)
        assert values[reg.COMMAND_IGNORED] == 0
        plc.start("SN-NEXT")
        values = plc.wait_state(FINISHED, 60)
        assert reg.State(values[reg.STATE]) == reg.State.ERROR
        assert values[reg.RESULT_CODE] == reg.RESULT_PUSH_PENDING
        assert values[reg.REASON_CODE] == reg.Reason.PUSH_PENDING
        assert _reason(values).startswith("start of SN-NEXT refused")
        assert not list(runs_dir.glob("SN-NEXT-*"))
        assert json.loads((runs_dir / "current.json").read_text())["run_dir"] == \
            str(run_dir)
        log = process.log.read_text()
        assert "start of SN-NEXT refused: the run of SN-R3 pushed offsets that are NOT " \
            "verified" in log and f"--resume {run_dir} --db " in log
    finally:
        plc.close()
    assert process.stop() == 0
    process.start()  # a restart resumes the pending run first (still estopped here)
    plc = Plc(config["modbus"]["port"])
    try:
        values = plc.wait_state(FINISHED, 120)
        assert reg.State(values[reg.STATE]) == reg.State.ERROR
        assert values[reg.OUTCOME_FLAGS] == reg.FLAG_PUSHED
        assert (runs_dir / "current.json").exists()  # still pending, still said
    finally:
        plc.close()


def _rollback(run_dir: Path, db: str) -> None:
    run = subprocess.run(hostpc_command("rollback", "--run", str(run_dir), "--db", db),
                         cwd=REPO, capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr


def _assert_rolled_back(values: list[int]) -> None:
    assert reg.State(values[reg.STATE]) == reg.State.FAIL
    assert values[reg.OUTCOME_FLAGS] & reg.FLAG_ROLLED_BACK
    assert not values[reg.OUTCOME_FLAGS] & reg.FLAG_VERIFIED
    assert values[reg.REASON_CODE] == reg.Reason.NOT_PUSHED
    assert _reason(values).startswith("ROLLED BACK")


@pytest.mark.slow
def test_a_pass_rolled_back_since_is_served_as_rolled_back(
        controller: StubFactory, station_on: StationFactory
        ) -> None:
    process, config = station_on(controller())
    db, runs_dir = str(config["db"]), Path(config["runs_dir"])
    plc = Plc(config["modbus"]["port"])
    try:
        values = plc.run("SN-R4")
        assert reg.State(values[reg.STATE]) == reg.State.PASS, process.log.read_text()[-3000:]
        assert values[reg.OUTCOME_FLAGS] == reg.FLAG_PUSHED | reg.FLAG_VERIFIED
    finally:
        plc.close()
    # rolled back while the station is stopped, before the PLC acknowledged the PASS
    assert process.stop() == 0
    (run_dir,) = runs_dir.glob("SN-R4-*/")
    _rollback(run_dir, db)
    process.start()
    plc = Plc(config["modbus"]["port"])
    try:
        deadline = time.monotonic() + 10
        while reg.State(plc.read()[reg.STATE]) == reg.State.PASS:
            assert time.monotonic() < deadline, "PASS served again for a rolled-back run"
            time.sleep(0.1)
        _assert_rolled_back(plc.read())
        plc.command(reg.Command.ACKNOWLEDGE)
        plc.wait_state({reg.State.IDLE}, 10)

        # rolled back while the station serves the PASS: the registers follow
        values = plc.run("SN-R5")
        assert reg.State(values[reg.STATE]) == reg.State.PASS, process.log.read_text()[-3000:]
        (run_dir,) = runs_dir.glob("SN-R5-*/")
        _rollback(run_dir, db)
        with open_archive(db, create=False) as archive:
            assert [r.verdict for r in archive.runs()] == ["ROLLED_BACK", "ROLLED_BACK"]
        deadline = time.monotonic() + 10
        while reg.State(plc.read()[reg.STATE]) == reg.State.PASS:
            assert time.monotonic() < deadline, "still PASS after the rollback"
            time.sleep(0.1)
        _assert_rolled_back(plc.read())
    finally:
        plc.close()
    assert process.stop() == 0
    process.start()  # not acknowledged: served again as the archive has it
    plc = Plc(config["modbus"]["port"])
    try:
        _assert_rolled_back(plc.read())
    finally:
        plc.close()


def _droppush_station(tmp_path: Path, station_on: StationFactory, **overrides: Any
                      ) -> tuple[StationProcess, dict[str, Any]]:
    """A sim station whose robot SN-DROPPUSH's link drops after the push, before the
    verification's verdict."""
    droppush = tmp_path / "droppush.json"
    droppush.write_text(json.dumps(_world(token=None, drop_after_requests=48)))
    return station_on("sim", sim={"scenarios_by_serial": {"SN-DROPPUSH": str(droppush)}},
                      **overrides)


@pytest.mark.slow
def test_a_sim_push_cut_off_is_pushed_again_on_the_resume(
        tmp_path: Path, station_on: StationFactory) -> None:
    process, config = _droppush_station(tmp_path, station_on, resume_attempts=2)
    values = run_one(config["modbus"]["port"], "SN-DROPPUSH")
    log = process.log.read_text()
    # its simulated controller ended with the run: the resume pushes again, verifies
    assert "the run ended with pushed offsets not verified (its simulated controller " \
        "with it: the resume pushes again)" in log, log[-3000:]
    assert "push lost" not in log
    assert reg.State(values[reg.STATE]) == reg.State.PASS, log[-3000:]
    assert values[reg.OUTCOME_FLAGS] == reg.FLAG_PUSHED | reg.FLAG_VERIFIED


@pytest.mark.slow
def test_a_failed_verification_names_the_pushed_joints_and_the_next_step(
        station_on: StationFactory) -> None:
    # a verification tolerance no fit meets: pushed, then FAIL
    process, config = station_on("sim", "--verify-tolerance", "0.001")
    values = run_one(config["modbus"]["port"], "SN-VF")
    log = process.log.read_text()
    assert reg.State(values[reg.STATE]) == reg.State.FAIL, log[-3000:]
    assert values[reg.RESULT_CODE] == 6
    assert values[reg.OUTCOME_FLAGS] == reg.FLAG_PUSHED  # not verified
    assert values[reg.JOINTS_CALIBRATED] == 0
    assert values[reg.JOINTS_PUSHED] & 0b011111 == 0b011111  # J1-J5: pushed, failed
    with open_archive(str(config["db"]), create=False) as archive:
        (run,) = archive.runs()
    reason = str(run.reason)
    assert reason.startswith("FAIL: the pushed offsets failed verification")
    assert "nothing to roll back" in reason and "START SN-VF again" in reason
    assert f"run of SN-VF: FAIL (result code 6, archive id 1): {reason}" in log


@pytest.mark.slow
def test_a_pending_sim_push_is_resumed_by_a_start_of_its_own_serial(
        tmp_path: Path, station_on: StationFactory) -> None:
    process, config = _droppush_station(tmp_path, station_on)  # no resume
    runs_dir = Path(config["runs_dir"])
    plc = Plc(config["modbus"]["port"])
    try:
        values = plc.run("SN-DROPPUSH")
        log = process.log.read_text()
        assert reg.State(values[reg.STATE]) == reg.State.ERROR, log[-3000:]
        assert values[reg.OUTCOME_FLAGS] == reg.FLAG_PUSHED
        (run_dir,) = runs_dir.glob("SN-DROPPUSH-*/")
        # a simulated controller ends with its run: settling it pushes again (--push)
        assert f"hostpc calibrate --resume {run_dir} --push --db " in log
        plc.command(reg.Command.ACKNOWLEDGE)
        plc.wait_state({reg.State.IDLE}, 10)
        values = plc.run("SN-DROPPUSH")  # the same robot again: its run is resumed, not a new one
        log = process.log.read_text()
        assert f"START SN-DROPPUSH: resuming its run {run_dir} first" in log
        assert reg.State(values[reg.STATE]) == reg.State.PASS, log[-3000:]
        assert values[reg.OUTCOME_FLAGS] == reg.FLAG_PUSHED | reg.FLAG_VERIFIED
        assert list(runs_dir.glob("SN-DROPPUSH-*/")) == [run_dir]
        assert not (runs_dir / "current.json").exists()  # settled
        with open_archive(str(config["db"]), create=False) as archive:
            assert [(r.id, r.verdict) for r in archive.runs()] == [(1, "PASS")]  # revised
        plc.command(reg.Command.ACKNOWLEDGE)
        plc.wait_state({reg.State.IDLE}, 10)
        values = plc.run("SN-NEXT")  # nothing pending: the next robot runs
        assert values[reg.RESULT_CODE] != reg.RESULT_PUSH_PENDING
        assert list(runs_dir.glob("SN-NEXT-*/"))
    finally:
        plc.close()


@pytest.mark.slow
def test_a_push_the_controller_did_not_store_is_not_resumed_but_rolled_back(
        controller: StubFactory, station_on: StationFactory) -> None:
    """The cell's controller stores every pushed offset clamped (ClampingProxy in front of
    the stub): the run ends on the read-back mismatch (push failed, result code 4). No
    resume settles that (it meets the clamped offsets again), so the station resumes it
    never, neither after the run (resume_attempts 1) nor on a START of the same robot: the
    START is refused (result 24) with the rollback that settles it, said whole once in the
    log; once rolled back, the next START runs."""
    from tests.integration.hostile_controller import ClampingProxy

    host, port = controller().split(":")
    with ClampingProxy((host, int(port))) as proxy:
        process, config = station_on(proxy.address, resume_attempts=1)
        runs_dir, db = Path(config["runs_dir"]), str(config["db"])
        plc = Plc(config["modbus"]["port"])
        try:
            values = plc.run("SN-CLAMP")
            log = process.log.read_text()
            assert reg.State(values[reg.STATE]) == reg.State.ERROR, log[-3000:]
            assert values[reg.RESULT_CODE] == 4 and proxy.clamped == 1  # never resumed
            assert "resuming (attempt" not in log
            (run_dir,) = runs_dir.glob("SN-CLAMP-*/")
            rollback = f"hostpc rollback --run {run_dir} --db "
            with open_archive(db, create=False) as archive:
                (row,) = archive.runs()
            assert row.reason is not None and row.reason.startswith("push failed"), row.reason
            assert "no resume settles it" in row.reason and rollback in row.reason
            journal = (run_dir / "journal.jsonl").read_text()
            plc.command(reg.Command.ACKNOWLEDGE)
            plc.wait_state({reg.State.IDLE}, 10)
            for _ in range(2):  # the same robot again: refused, not resumed
                plc.start("SN-CLAMP")
                values = plc.wait_state(FINISHED, 60)
                assert values[reg.RESULT_CODE] == reg.RESULT_PUSH_PENDING
                assert values[reg.REASON_CODE] == reg.Reason.PUSH_PENDING
                plc.command(reg.Command.ACKNOWLEDGE)
                plc.wait_state({reg.State.IDLE}, 10)
            assert (run_dir / "journal.jsonl").read_text() == journal  # no resume ran
            assert proxy.clamped == 1 and list(runs_dir.glob("SN-CLAMP-*/")) == [run_dir]
            log = process.log.read_text()
            assert log.count("start of SN-CLAMP refused: the run of SN-CLAMP pushed offsets "
                             "that are NOT stored as asked (push failed); no resume "
                             "settles it") == 1, log[-3000:]
        finally:
            plc.close()
        assert process.stop() == 0
        process.start()  # a restart does not resume it either
        plc = Plc(config["modbus"]["port"])
        try:
            plc.start("SN-CLAMP")
            values = plc.wait_state(FINISHED, 60)
            assert values[reg.RESULT_CODE] == reg.RESULT_PUSH_PENDING
            assert (run_dir / "journal.jsonl").read_text() == journal
            assert f"the run of SN-CLAMP in {run_dir} is not resumed" in process.log.read_text()
            plc.command(reg.Command.ACKNOWLEDGE)
            plc.wait_state({reg.State.IDLE}, 10)
            _rollback(run_dir, db)
            plc.start("SN-CLAMP")  # settled: a new run of the robot
            plc.wait_state(FINISHED, 300)
            assert len(list(runs_dir.glob("SN-CLAMP-*/"))) == 2
        finally:
            plc.close()
