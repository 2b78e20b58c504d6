"""A station checks its whole configuration when it starts: a config that would fail every
run (a missing rig file, cell reference or scenario, an archive it cannot open, a port it
cannot listen on) is refused at start with one line naming the key, exit code 2, and
nothing is created (no archive, no runs folder)."""

from __future__ import annotations

import socket
import subprocess
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
import yaml

from hostpc.station import registers as reg
from tests.station.conftest import REPO, hostpc_command


@pytest.fixture
def taken_port() -> Iterator[int]:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        yield int(s.getsockname()[1])


def _start(tmp_path: Path, **config: Any) -> subprocess.CompletedProcess[str]:
    base: dict[str, Any] = {"station": "cell-7", "robot": "sim", "db": "sqlite:///station.db",
                            "runs_dir": "station-runs",
                            "modbus": {"host": "127.0.0.1", "port": 0}}
    path = tmp_path / "station.yaml"
    path.write_text(yaml.safe_dump({**base, **config}))
    return subprocess.run(hostpc_command("station", "--config", str(path)), cwd=REPO,
                          capture_output=True, text=True, timeout=60)


def _refused(run: subprocess.CompletedProcess[str], tmp_path: Path, key: str,
             *words: str) -> None:
    lines = run.stderr.splitlines()
    assert run.returncode == 2, (run.returncode, run.stderr)
    assert len(lines) == 1 and run.stdout == "", run.stderr + run.stdout
    assert lines[0].startswith(f"hostpc station: error: {tmp_path / 'station.yaml'}: {key}: "), \
        lines[0]
    assert all(word in lines[0] for word in words), lines[0]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["station.yaml"]  # nothing created


def test_a_missing_rig_file_is_refused_at_start(tmp_path: Path) -> None:
    run = _start(tmp_path, calibrate_args=["--rig", "/etc/zerocal/rig.json"])
    _refused(run, tmp_path, "calibrate_args", "/etc/zerocal/rig.json", "no such file")


def test_a_missing_cell_reference_is_refused_at_start(tmp_path: Path) -> None:
    run = _start(tmp_path, calibrate_args=["--reference", str(tmp_path / "ref.json")])
    _refused(run, tmp_path, "calibrate_args", "--reference", "ref.json")


def test_options_the_station_sets_name_their_own_key(tmp_path: Path) -> None:
    _refused(_start(tmp_path, effects="+no_such_effect"), tmp_path, "effects",
             "no_such_effect")
    _refused(_start(tmp_path, method="no_such_method"), tmp_path, "method", "no_such_method")


def test_a_missing_sim_scenario_is_refused_at_start(tmp_path: Path) -> None:
    run = _start(tmp_path, sim={"scenarios_by_serial": {"SN-1": "gone.yaml"}})
    _refused(run, tmp_path, "sim.scenarios_by_serial.SN-1", "gone.yaml")


def test_an_archive_that_cannot_be_opened_is_refused_at_start(tmp_path: Path) -> None:
    run = _start(tmp_path, db=f"sqlite:///{tmp_path / 'no-such-folder' / 'station.db'}")
    _refused(run, tmp_path, "db", "cannot open")


def test_ports_in_use_are_refused_at_start(tmp_path: Path, taken_port: int) -> None:
    _refused(_start(tmp_path, modbus={"host": "127.0.0.1", "port": taken_port}), tmp_path,
             "modbus", f"127.0.0.1:{taken_port}", "cannot listen")
    _refused(_start(tmp_path, http=f"127.0.0.1:{taken_port}"), tmp_path, "http",
             f"127.0.0.1:{taken_port}", "cannot listen")
    _refused(_start(tmp_path, http="8080"), tmp_path, "http", "HOST:PORT")


def test_a_failed_runs_reason_is_on_the_registers() -> None:
    reason = "/tmp/cell/rig.json: cannot read rig file (no such file); the station's rig"
    values = reg.outcome_registers(reg.RunOutcome(reg.State.ERROR, 2, reason=reason))
    assert values[reg.REASON_CODE] == reg.Reason.INPUT
    text = reg.decode_text([values[a] for a in range(reg.REASON, reg.REASON
                                                      + reg.REASON_LENGTH)])
    assert text == reason[:2 * reg.REASON_LENGTH]
    aborted = reg.outcome_registers(reg.RunOutcome(reg.State.ERROR, reg.RESULT_ABORTED))
    assert aborted[reg.REASON_CODE] == reg.Reason.ABORTED
    passed = reg.outcome_registers(reg.RunOutcome(reg.State.PASS, 0))
    assert passed[reg.REASON_CODE] == reg.Reason.NONE and passed[reg.REASON] == 0
    # the reason registers come after every register of the old map
    assert reg.REASON_CODE == 18 and reg.REASON >= reg.MODEL + reg.MODEL_LENGTH
    assert reg.REASON + reg.REASON_LENGTH <= reg.N_REGISTERS <= 125  # one Modbus read
