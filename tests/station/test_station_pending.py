"""A run pending with pushed offsets not verified, after its controller restarted: the
station reads what the controller holds (through the resume, which compares it with the
run's journal) and names, and takes, the one action that settles it. A controller back at
the run's previous offsets (the push lost) is pushed again and verified; a controller at
offsets that are neither the run's previous nor its pushed ones cannot be settled by a
resume: the run is archived ERROR with what the controller holds, and an ACKNOWLEDGE
releases it (the next robot is no longer refused). Real `controller-stub serve` (port 0,
restarted on the port it got), real station process, real pymodbus client, real SQLite
archive."""

from __future__ import annotations

import json
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

from hostpc.archive import open_archive
from hostpc.robots.simulator import default_sim_scenario
from hostpc.station import registers as reg
from tests.station.conftest import REPO, StationFactory
from tests.station.plc_client import Plc
from tests.station.test_station_truths import FINISHED, LISTENING, TOKEN

Restart = Callable[..., None]


class Controller:
    """One cell controller (`controller-stub serve`): started on port 0, restarted (a
    controller power-cycled) on the port it got, with its world's initial offsets or
    `initial_offsets` (rad)."""

    def __init__(self, folder: Path):
        self.folder = folder
        self.process: subprocess.Popen[str] | None = None
        self.address = ""
        self.starts = 0

    def serve(self, initial_offsets: list[float] | None = None, **faults: int) -> str:
        world = default_sim_scenario()
        world["target"] = {**world["target"], "centre_error": [0.0, 0.0, 0.0]}
        world["server"] = {**world.get("server", {}), "token": TOKEN}
        if initial_offsets is not None:
            world["server"]["initial_offsets"] = initial_offsets
        if faults:
            world["faults"] = dict(faults)
        scenario = self.folder / f"world{self.starts}.json"
        scenario.write_text(json.dumps(world))
        self.starts += 1
        port = self.address.rpartition(":")[2] if self.address else "0"
        self.process = subprocess.Popen(
            [sys.executable, "-m", "controller_stub", "serve", "--scenario", str(scenario),
             "--port", port], cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
            text=True)
        assert self.process.stdout is not None
        match = LISTENING.search(self.process.stdout.readline())
        assert match, self.process.stderr.read() if self.process.stderr else ""
        self.address = f"{match['host']}:{match['port']}"
        return self.address

    def restart(self, initial_offsets: list[float] | None = None) -> None:
        """Kill it (kill -9: a power loss) and start it again, fault free."""
        self.stop(kill=True)
        self.serve(initial_offsets)

    def stop(self, kill: bool = False) -> None:
        if self.process is not None and self.process.poll() is None:
            if kill:
                self.process.kill()
            else:
                self.process.terminate()
            self.process.wait(timeout=10)


@pytest.fixture
def controller(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[Controller]:
    monkeypatch.setenv("ZEROCAL_TOKEN", TOKEN)
    cell = Controller(tmp_path)
    yield cell
    cell.stop()


def _pending_station(controller: Controller, make_station: StationFactory,
                     resume_attempts: int = 0) -> tuple[Any, dict[str, Any], Plc, Path]:
    """A station whose run of SN-P1 pushed and was estopped verifying (its resumes estopped
    too): pending, its pushed offsets not verified; the PLC acknowledged it."""
    process, config = make_station(station="eol-pending",
                                   robot=controller.serve(estop_after_moves=15),
                                   require_joints="1,2,3,4,5",
                                   resume_attempts=resume_attempts)
    plc = Plc(config["modbus"]["port"])
    values = plc.run("SN-P1")
    runs_dir = Path(config["runs_dir"])
    assert reg.State(values[reg.STATE]) == reg.State.ERROR, process.log.read_text()[-3000:]
    assert values[reg.OUTCOME_FLAGS] == reg.FLAG_PUSHED
    assert (runs_dir / "current.json").exists()
    (run_dir,) = runs_dir.glob("SN-P1-*/")
    plc.command(reg.Command.ACKNOWLEDGE)
    plc.wait_state({reg.State.IDLE}, 10)
    return process, config, plc, run_dir


def _reason(values: list[int]) -> str:
    return reg.decode_text(values[reg.REASON:reg.REASON + reg.REASON_LENGTH])


@pytest.mark.slow
def test_a_push_lost_to_a_restarted_controller_is_pushed_again_and_verified(
        controller: Controller, make_station: StationFactory) -> None:
    """Review F4 (a): the controller restarted with the run's previous offsets; every step
    the station named (START the robot again, `calibrate --resume DIR --db URL`) ended
    "push lost" again. Now the step named is the push again, and START takes it."""
    process, config, plc, run_dir = _pending_station(controller, make_station)
    runs_dir = Path(config["runs_dir"])
    try:
        controller.restart()  # back at the world's initial offsets: the run's previous
        values = plc.run("SN-P1")  # the station resumes its run: the push is lost
        log = process.log.read_text()
        assert reg.State(values[reg.STATE]) == reg.State.ERROR, log[-3000:]
        assert values[reg.REASON_CODE] == reg.Reason.PUSH_LOST
        with open_archive(str(config["db"]), create=False) as archive:
            row = archive.runs()[0]
        assert row.reason is not None
        assert f"hostpc calibrate --resume {run_dir} --push --db " in row.reason
        assert f"hostpc calibrate --resume {run_dir} --db " not in row.reason
        assert "hostpc rollback" not in row.reason.split("station:", 1)[1]
        assert "the controller has the run's previous offsets again" in log
        assert (runs_dir / "current.json").exists()  # still pending: nothing verified
        plc.command(reg.Command.ACKNOWLEDGE)
        plc.wait_state({reg.State.IDLE}, 10)

        values = plc.run("SN-P1")  # the step named: the station pushes again, verifies
        log = process.log.read_text()
        assert reg.State(values[reg.STATE]) == reg.State.PASS, log[-3000:]
        assert values[reg.OUTCOME_FLAGS] & reg.FLAG_PUSHED
        assert values[reg.OUTCOME_FLAGS] & reg.FLAG_VERIFIED
        assert not (runs_dir / "current.json").exists()  # settled
        assert f"START SN-P1: resuming its run {run_dir} first (its push was lost: pushing " \
            "again)" in log
    finally:
        plc.close()


@pytest.mark.slow
def test_a_restarted_station_pushes_a_lost_push_again_itself(
        controller: Controller, make_station: StationFactory) -> None:
    """Review F4 (a), the station restarted too: it resumed the run twice without --push,
    "push lost" both times. Now the resume that finds the push lost is followed by the
    push again (as for a simulated robot), its resumes used up or not."""
    process, config, plc, run_dir = _pending_station(controller, make_station,
                                                     resume_attempts=1)
    plc.close()
    runs_dir = Path(config["runs_dir"])
    assert process.stop() == 0
    controller.restart()  # back at the run's previous offsets
    process.start()  # resumes the pending run first
    plc = Plc(config["modbus"]["port"])
    try:
        values = plc.wait_state(FINISHED, 300)
        log = process.log.read_text()
        assert reg.State(values[reg.STATE]) == reg.State.PASS, log[-3000:]
        assert "push lost during the run of SN-P1 (the controller has the run's previous " \
            "offsets again): pushing them again and verifying" in log
        assert not (runs_dir / "current.json").exists()
        with open_archive(str(config["db"]), create=False) as archive:
            (row,) = archive.runs()
        assert (row.verdict, row.push_status, row.run_dir) == ("PASS", "pushed", str(run_dir))
    finally:
        plc.close()


@pytest.mark.slow
def test_a_controller_at_other_offsets_releases_the_pending_run_on_acknowledge(
        controller: Controller, make_station: StationFactory) -> None:
    """Review F4 (b): the controller restarted with offsets that are neither the run's
    previous nor its pushed ones: the resume cannot settle the run, yet the station refused
    every other robot (code 24) and named that resume. Now the run is archived ERROR with
    what the controller holds, REASON_CODE says so, and ACKNOWLEDGE releases it."""
    process, config, plc, run_dir = _pending_station(controller, make_station)
    runs_dir = Path(config["runs_dir"])
    try:
        controller.restart(initial_offsets=[0.003, -0.002, 0.001, 0.002, -0.001, 0.0])
        plc.start("SN-OTHER")  # refused, naming the resume (what holds it is not known)
        values = plc.wait_state(FINISHED, 60)
        assert values[reg.RESULT_CODE] == reg.RESULT_PUSH_PENDING
        plc.command(reg.Command.ACKNOWLEDGE)
        plc.wait_state({reg.State.IDLE}, 10)

        values = plc.run("SN-P1")  # its resume finds the controller at other offsets
        log = process.log.read_text()
        assert reg.State(values[reg.STATE]) == reg.State.ERROR, log[-3000:]
        assert values[reg.RESULT_CODE] == 2
        with open_archive(str(config["db"]), create=False) as archive:
            row = archive.runs()[0]
        assert row.verdict == "ERROR" and row.reason is not None
        assert "now [+0.1719, -0.1146, +0.0573, +0.1146, -0.0573, +0.0000] deg" in row.reason
        step = row.reason.split("station:", 1)[1]
        assert "ACKNOWLEDGE" in step and "--resume" not in step
        assert "holds pushed offsets not yet verified" not in log
        assert "neither the run's previous nor its pushed offsets" in log
        assert values[reg.REASON_CODE] == reg.Reason.OFFSETS_CHANGED
        assert (runs_dir / "current.json").exists()  # held until the operator's ACK

        plc.command(reg.Command.ACKNOWLEDGE)  # the operator's action: released
        plc.wait_state({reg.State.IDLE}, 10)
        assert not (runs_dir / "current.json").exists()
        assert "released by ACKNOWLEDGE" in process.log.read_text()
        plc.start("SN-OTHER")  # the next robot is taken
        deadline = time.monotonic() + 30
        while not list(runs_dir.glob("SN-OTHER-*")):
            assert time.monotonic() < deadline, process.log.read_text()[-3000:]
            time.sleep(0.2)
        values = plc.wait_state(FINISHED, 300)
        assert values[reg.RESULT_CODE] != reg.RESULT_PUSH_PENDING
    finally:
        plc.close()
