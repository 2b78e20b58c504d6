"""`hostpc station` end to end: a real pymodbus client as the PLC, the simulated controller
as the robots, a real SQLite archive; 20 robots in a row, one with a hidden effect (FAIL),
one whose controller dies mid-run (resumed); a station restarted mid-run resumes the run."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
import yaml

from hostpc.archive import open_archive
from hostpc.robots.simulator import default_sim_scenario, packaged_default_scenario
from hostpc.station import registers as reg
from tests.station.conftest import REPO, hostpc_command
from tests.station.plc_client import Plc


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _rss_kb(pid: int) -> int:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1])
    raise AssertionError("no VmRSS")


def _hidden_compliance_world() -> dict[str, object]:
    world = packaged_default_scenario("stereo_hidden_compliance.yaml")
    base = default_sim_scenario()
    world["target"] = base["target"]  # the cell's target is surveyed (known), as for all
    world["motion"] = base["motion"]
    return world


class StationProcess:
    def __init__(self, config: Path, log: Path):
        self.config, self.log = config, log
        self.process: subprocess.Popen[bytes] | None = None

    def start(self) -> None:
        with self.log.open("ab") as log:
            self.process = subprocess.Popen(hostpc_command("station", "--config", str(self.config)),
                                            cwd=REPO, stdout=log, stderr=subprocess.STDOUT)
        deadline = time.monotonic() + 60
        while b"PLC registers on" not in self.log.read_bytes().split(b"stopped")[-1]:
            assert self.process.poll() is None, self.log.read_text()[-3000:]
            assert time.monotonic() < deadline, "station did not start"
            time.sleep(0.1)

    def stop(self, sig: int = signal.SIGTERM) -> int:
        assert self.process is not None
        self.process.send_signal(sig)
        return self.process.wait(timeout=120)


@pytest.fixture
def station(tmp_path: Path, fast_rig: Path) -> Iterator[tuple[StationProcess, dict[str, object]]]:
    hidden = tmp_path / "hidden.json"
    hidden.write_text(json.dumps(_hidden_compliance_world()))
    port = _free_port()
    # J6 is not separable from the estimated tool frame in this cell: require J1-J5
    config = {"station": "eol-1", "robot": "sim", "known": "target", "poses": 12,
              "require_joints": "1,2,3,4,5",
              "verify_poses": 4, "calibrate_args": ["--rig", str(fast_rig)],
              "db": f"sqlite:///{tmp_path / 'archive.db'}", "runs_dir": str(tmp_path / "runs"),
              "modbus": {"host": "127.0.0.1", "port": port},
              "sim": {"scenarios_by_serial": {"SN-HIDDEN": str(hidden)}}}
    path = tmp_path / "station.yaml"
    path.write_text(yaml.safe_dump(config))
    process = StationProcess(path, tmp_path / "station.log")
    process.start()
    yield process, config
    if process.process is not None and process.process.poll() is None:
        process.stop(signal.SIGKILL)


def _kill_controller_of(run_dir: Path) -> None:
    """Kill the simulated controller serving the run in `run_dir`: a controller_stub process
    whose own command line names the run's scenario, or (a warm simulator, handed its
    arguments on stdin: hostpc/robots/warm_stub.py) whose parent's names the run folder."""
    marker = str(run_dir / "sim" / "scenario.json")

    def cmdline(pid: str) -> str:
        try:
            return Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode()
        except OSError:
            return ""

    def parent(pid: str) -> str:
        try:
            return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[1]
        except (OSError, IndexError):
            return ""

    for pid in os.listdir("/proc"):
        if not pid.isdigit():
            continue
        line = cmdline(pid)
        if "controller_stub" in line and (marker in line
                                          or str(run_dir) in cmdline(parent(pid))):
            os.kill(int(pid), signal.SIGKILL)
            return
    raise AssertionError(f"no simulated controller for {run_dir}")


def _wait_samples(runs_dir: Path, serial: str, n: int, timeout: float = 120) -> Path:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        for run_dir in runs_dir.glob(f"{serial}-*"):
            journal = run_dir / "journal.jsonl"
            if run_dir.is_dir() and journal.exists() and \
                    journal.read_text().count('"event":"sample"') >= n:
                return run_dir
        time.sleep(0.05)
    raise AssertionError(f"run of {serial} never reached {n} samples")


@pytest.mark.slow
def test_twenty_robots_in_a_row(station: tuple[StationProcess, dict[str, object]]) -> None:
    process, config = station
    assert process.process is not None
    plc = Plc(config["modbus"]["port"])  # type: ignore[index]
    serials = [f"SN-{k:03d}" for k in range(20)]
    serials[7], dropped = "SN-HIDDEN", "SN-012"
    runs_dir = Path(str(config["runs_dir"]))
    beat = plc.read()[reg.HEARTBEAT]
    rss_after_first = 0
    try:
        for index, serial in enumerate(serials):
            plc.start(serial)
            if serial == dropped:
                _kill_controller_of(_wait_samples(runs_dir, serial, 5))
            values = plc.wait_state({reg.State.PASS, reg.State.FAIL, reg.State.ERROR}, 300)
            state = reg.State(values[reg.STATE])
            expected = reg.State.FAIL if serial == "SN-HIDDEN" else reg.State.PASS
            assert state == expected, (serial, values[:14], process.log.read_text()[-2000:])
            assert values[reg.RESULT_CODE] == (0 if expected == reg.State.PASS else
                                               values[reg.RESULT_CODE])
            assert values[reg.RUN_COUNTER] == index + 1
            if expected == reg.State.PASS:
                correction = reg.decode_int32(values[reg.LARGEST_CORRECTION:
                                                     reg.LARGEST_CORRECTION + 2]) / 1e4
                assert 0.05 < correction < 1.0  # uniform +-0.5 deg zero errors
            assert reg.decode_int32(values[reg.ARCHIVE_ID:reg.ARCHIVE_ID + 2]) == index + 1
            plc.command(reg.Command.ACKNOWLEDGE)
            plc.wait_state({reg.State.IDLE}, 10)
            if index == 0:
                rss_after_first = _rss_kb(process.process.pid)
        growth_mb = (_rss_kb(process.process.pid) - rss_after_first) / 1024
        assert growth_mb < 20, f"station RSS grew {growth_mb:.1f} MB over 20 runs"
        assert plc.read()[reg.HEARTBEAT] != beat
        # a read-only register refuses a PLC write
        assert plc.client.write_register(reg.STATE, 2).isError()
    finally:
        plc.close()
    assert process.stop() == 0
    with open_archive(str(config["db"])) as archive:
        runs = archive.runs()
    assert [r.serial for r in runs] == serials
    # its model does not explain the data: the push is refused (offsets unchanged)
    assert {r.serial: r.verdict for r in runs}["SN-HIDDEN"] == "REFUSED"
    assert all(r.verdict == "PASS" for r in runs if r.serial != "SN-HIDDEN")
    assert "resuming (attempt 1 of 2)" in process.log.read_text()
    assert len({r.run_uid for r in runs}) == 20


@pytest.mark.slow
def test_a_restarted_station_resumes_the_interrupted_run(
        station: tuple[StationProcess, dict[str, object]]) -> None:
    process, config = station
    plc = Plc(config["modbus"]["port"])  # type: ignore[index]
    runs_dir = Path(str(config["runs_dir"]))
    try:
        plc.start("SN-RESTART")
        _wait_samples(runs_dir, "SN-RESTART", 4)
    finally:
        plc.close()
    assert process.stop(signal.SIGTERM) == 0  # graceful: the run stays resumable
    assert (runs_dir / "current.json").exists()
    process.start()
    plc = Plc(config["modbus"]["port"])  # type: ignore[index]
    try:
        values = plc.wait_state({reg.State.PASS, reg.State.FAIL, reg.State.ERROR}, 300)
        assert reg.State(values[reg.STATE]) == reg.State.PASS, process.log.read_text()[-2000:]
        # a start without a serial is a result code, never a dead station
        plc.command(reg.Command.ACKNOWLEDGE)
        plc.wait_state({reg.State.IDLE}, 10)
        plc.client.write_registers(reg.SERIAL, [0] * reg.SERIAL_LENGTH)
        plc.command(reg.Command.START)
        values = plc.wait_state({reg.State.ERROR}, 10)
        assert values[reg.RESULT_CODE] == reg.RESULT_NO_SERIAL
    finally:
        plc.close()
    assert process.stop() == 0
    with open_archive(str(config["db"])) as archive:
        runs = archive.runs()
    assert [r.serial for r in runs] == ["SN-RESTART"]
    assert not (runs_dir / "current.json").exists()


CHROMIUM_FLAGS = ["--headless", "--no-sandbox", "--disable-gpu",
                  "--disable-background-networking", "--disable-component-update",
                  "--disable-sync", "--no-first-run"]


@pytest.mark.slow
def test_live_page_shows_state_and_verdicts_in_chromium(tmp_path: Path, fast_rig: Path) -> None:
    import shutil
    import urllib.request

    browser = shutil.which("chromium") or shutil.which("chromium-browser")
    if browser is None:
        if os.environ.get("ZEROCAL_REQUIRE_BROWSER"):
            pytest.fail("chromium is not installed but ZEROCAL_REQUIRE_BROWSER is set")
        pytest.skip("chromium is not installed (apt-get install -y chromium)")
    modbus, http = _free_port(), _free_port()
    config = {"station": "eol-page", "robot": "sim", "known": "target", "poses": 10,
              "verify_poses": 3, "calibrate_args": ["--rig", str(fast_rig)],
              "require_joints": "1,2,3,4,5",  # J6: the tool is estimated
              "db": f"sqlite:///{tmp_path / 'archive.db'}", "runs_dir": str(tmp_path / "runs"),
              "modbus": {"host": "127.0.0.1", "port": modbus}, "http": f"127.0.0.1:{http}"}
    path = tmp_path / "station.yaml"
    path.write_text(yaml.safe_dump(config))
    process = StationProcess(path, tmp_path / "station.log")
    process.start()
    try:
        plc = Plc(modbus)
        for serial in ("SN-PAGE-1", "SN-PAGE-2"):
            plc.start(serial)
            plc.wait_state({reg.State.PASS, reg.State.FAIL, reg.State.ERROR}, 300)
            if serial == "SN-PAGE-1":
                plc.command(reg.Command.ACKNOWLEDGE)
                plc.wait_state({reg.State.IDLE}, 10)
        plc.close()
        url = f"http://127.0.0.1:{http}/"
        state = json.loads(urllib.request.urlopen(url + "api/state", timeout=10).read())
        assert state["state"] == "PASS" and state["serial"] == "SN-PAGE-2"
        png = urllib.request.urlopen(url + "drift/SN-PAGE-1.png", timeout=30).read()
        assert png.startswith(b"\x89PNG")
        dom = subprocess.run([browser, *CHROMIUM_FLAGS, f"--user-data-dir={tmp_path / 'p1'}",
                              "--virtual-time-budget=5000", "--dump-dom", url],
                             capture_output=True, text=True, timeout=120)
        assert dom.returncode == 0, dom.stderr[-2000:]
        assert 'id="state" class="PASS">PASS<' in dom.stdout, dom.stdout[-3000:]
        assert "SN-PAGE-1" in dom.stdout and "SN-PAGE-2" in dom.stdout
        shot = tmp_path / "station-page.png"
        subprocess.run([browser, *CHROMIUM_FLAGS, f"--user-data-dir={tmp_path / 'p2'}",
                        "--virtual-time-budget=5000", "--window-size=1000,1100",
                        f"--screenshot={shot}", url], capture_output=True, timeout=120)
        assert shot.is_file() and shot.stat().st_size > 10_000
        if os.environ.get("ZEROCAL_KEEP_SCREENSHOT"):
            shutil.copy(shot, os.environ["ZEROCAL_KEEP_SCREENSHOT"])
    finally:
        assert process.stop() == 0
