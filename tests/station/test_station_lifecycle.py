"""A station driven through start, a run that fails anyway, an abort and idle, with a real
pymodbus client as the PLC and headless Chromium reading the live page at each step:
the page shows exactly the station's state (idle is idle: no stale progress bar, no CLI
resume hint the station already acted on); a failing run's one-line reason is in the
station log, the page, the archive and the registers; every run has a report.html,
linked from the live page and from `hostpc history --html`, opened in Chromium."""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import urllib.request
from pathlib import Path
from typing import Any

import pytest
import yaml

from hostpc.archive import open_archive
from hostpc.station import registers as reg
from tests.station.conftest import REPO, hostpc_command
from tests.station.plc_client import Plc
from tests.station.test_station import (
    CHROMIUM_FLAGS,
    StationProcess,
    _free_port,
    _wait_samples,
)

FINISHED = {reg.State.PASS, reg.State.FAIL, reg.State.ERROR}


def _browser() -> str:
    browser = shutil.which("chromium") or shutil.which("chromium-browser")
    if browser is None:
        if os.environ.get("ZEROCAL_REQUIRE_BROWSER"):
            pytest.fail("chromium is not installed but ZEROCAL_REQUIRE_BROWSER is set")
        pytest.skip("chromium is not installed (apt-get install -y chromium)")
    return browser


class Page:
    """Headless Chromium on a URL: the DOM after the page's scripts ran."""

    def __init__(self, browser: str, profiles: Path):
        self.browser, self.profiles, self.count = browser, profiles, 0

    def dom(self, url: str) -> str:
        self.count += 1
        run = subprocess.run([self.browser, *CHROMIUM_FLAGS,
                              f"--user-data-dir={self.profiles / str(self.count)}",
                              "--virtual-time-budget=3000", "--dump-dom", url],
                             capture_output=True, text=True, timeout=120)
        assert run.returncode == 0, run.stderr[-2000:]
        return run.stdout


def _element(dom: str, element_id: str) -> str:
    """The opening tag of the element with `element_id` (its attributes: hidden, class)."""
    match = re.search(rf'<[a-z]+ id="{element_id}"[^>]*>', dom)
    assert match, f"no #{element_id} in {dom[-3000:]}"
    return match.group(0)


def _text(dom: str, element_id: str) -> str:
    match = re.search(rf'<([a-z]+) id="{element_id}"[^>]*>(.*?)</\1>', dom, re.S)
    assert match, f"no #{element_id} in {dom[-3000:]}"
    return re.sub(r"<[^>]+>", "", match.group(2)).strip()


def _state(url: str) -> dict[str, Any]:
    return dict(json.loads(urllib.request.urlopen(url + "api/state", timeout=10).read()))


def _reason_registers(values: list[int]) -> str:
    return reg.decode_text(values[reg.REASON:reg.REASON + reg.REASON_LENGTH])


@pytest.mark.slow
def test_station_page_through_start_failure_abort_and_idle(tmp_path: Path,
                                                           fast_rig: Path) -> None:
    page = Page(_browser(), tmp_path / "profiles")
    rig = tmp_path / "cell-rig.json"  # the cell's rig file: it goes missing mid-shift
    shutil.copy(fast_rig, rig)
    modbus, http = _free_port(), _free_port()
    runs_dir = tmp_path / "runs"
    db = f"sqlite:///{tmp_path / 'archive.db'}"
    config = {"station": "eol-life", "robot": "sim", "known": "target", "poses": 10,
              "verify_poses": 3, "require_joints": "1,2,3,4,5",  # J6: tool estimated
              "calibrate_args": ["--rig", str(rig)], "db": db, "runs_dir": str(runs_dir),
              "modbus": {"host": "127.0.0.1", "port": modbus}, "http": f"127.0.0.1:{http}"}
    path = tmp_path / "station.yaml"
    path.write_text(yaml.safe_dump(config))
    process = StationProcess(path, tmp_path / "station.log")
    process.start()
    url = f"http://127.0.0.1:{http}/"
    plc = Plc(modbus)
    try:
        # idle at start: nothing of any run
        dom = page.dom(url)
        assert 'class="IDLE">IDLE<' in dom, dom[-3000:]
        assert "hidden" in _element(dom, "running") and "hidden" in _element(dom, "result")

        # start: RUNNING with its progress bar and the robot
        plc.start("SN-LIFE-PASS")
        _wait_samples(runs_dir, "SN-LIFE-PASS", 2)
        dom = page.dom(url)
        running = 'class="RUNNING">RUNNING<' in dom
        assert running or _state(url)["state"] != "RUNNING", dom[-3000:]
        if running:  # (else the run finished while Chromium read the page)
            assert "hidden" not in _element(dom, "running"), dom[-3000:]
            assert _text(dom, "serial") == "SN-LIFE-PASS"
            assert "hidden" in _element(dom, "result")
        values = plc.wait_state(FINISHED, 300)
        assert reg.State(values[reg.STATE]) == reg.State.PASS, process.log.read_text()[-3000:]
        assert values[reg.REASON_CODE] == reg.Reason.NONE and not _reason_registers(values)
        dom = page.dom(url)
        assert 'class="PASS">PASS<' in dom and "hidden" in _element(dom, "running")
        passed = _state(url)
        assert passed["report"] and passed["reason"] == ""
        report = page.dom(url.rstrip("/") + passed["report"])
        assert "zerocal calibration:" in report  # calibrate's own report of the run
        plc.command(reg.Command.ACKNOWLEDGE)
        plc.wait_state({reg.State.IDLE}, 10)

        # a run that fails anyway: the rig file is gone after the station started
        rig.unlink()
        plc.start("SN-LIFE-FAIL")
        values = plc.wait_state(FINISHED, 120)
        assert reg.State(values[reg.STATE]) == reg.State.ERROR
        assert values[reg.RESULT_CODE] == 2 and values[reg.REASON_CODE] == reg.Reason.INPUT
        failed = _state(url)
        reason = failed["reason"]
        assert str(rig) in reason and "no such file" in reason and "\n" not in reason
        assert reason.startswith(_reason_registers(values)) and _reason_registers(values)
        assert f"run of SN-LIFE-FAIL: ERROR (result code 2, archive id 2): {reason}" in \
            process.log.read_text()
        dom = page.dom(url)
        assert 'class="ERROR">ERROR<' in dom and _text(dom, "reason") == reason
        assert "hidden" not in _element(dom, "result") and "hidden" in _element(dom, "running")
        station_report = page.dom(url.rstrip("/") + failed["report"])
        assert "zerocal station run of SN-LIFE-FAIL: ERROR" in station_report
        assert reason in station_report.replace("&amp;", "&")
        plc.command(reg.Command.ACKNOWLEDGE)
        plc.wait_state({reg.State.IDLE}, 10)
        shutil.copy(fast_rig, rig)

        # abort: the run is interrupted before its push
        plc.start("SN-LIFE-ABORT")
        _wait_samples(runs_dir, "SN-LIFE-ABORT", 3)
        plc.command(reg.Command.ABORT)
        values = plc.wait_state(FINISHED, 120)
        assert reg.State(values[reg.STATE]) == reg.State.ERROR
        assert values[reg.RESULT_CODE] == reg.RESULT_ABORTED
        assert values[reg.REASON_CODE] == reg.Reason.ABORTED
        dom = page.dom(url)
        assert 'class="ERROR">ERROR<' in dom and "aborted by the PLC" in _text(dom, "reason")
        assert "hidden" in _element(dom, "running") and "--resume" not in dom

        # idle again: nothing of the aborted run but its row in the table of last robots
        plc.command(reg.Command.ACKNOWLEDGE)
        values = plc.wait_state({reg.State.IDLE}, 10)
        assert values[reg.PROGRESS] == 0 and values[reg.REASON_CODE] == 0
        assert not _reason_registers(values)
        idle = _state(url)
        assert (idle["progress"], idle["last_line"], idle["serial"], idle["reason"]) == (
            0, "", "", "")
        dom = page.dom(url)
        assert 'class="IDLE">IDLE<' in dom, dom[-3000:]
        assert "hidden" in _element(dom, "running") and "hidden" in _element(dom, "result")
        assert "hidden" in _element(dom, "robot-line") and _text(dom, "line") == ""
        assert "--resume" not in dom and " %<" not in dom
        assert dom.count('class="report"') == 3  # every run in the table links its report
    finally:
        plc.close()
        assert process.stop() == 0

    # the archive: every run, its reason, its report
    with open_archive(db, create=False) as archive:
        runs = archive.runs()
    assert [(r.serial, r.verdict) for r in runs] == [
        ("SN-LIFE-PASS", "PASS"), ("SN-LIFE-FAIL", "ERROR"), ("SN-LIFE-ABORT", "ERROR")]
    assert runs[0].reason is None and runs[1].reason == reason
    assert "aborted by the PLC" in str(runs[2].reason)
    assert all(Path(str(r.report_path)).is_file() for r in runs)

    # hostpc history --html links every run's report; Chromium opens one from it
    history = tmp_path / "history.html"
    run = subprocess.run(hostpc_command("history", "--db", db, "--html", str(history)),
                         cwd=REPO, capture_output=True, text=True, timeout=120)
    assert run.returncode in (0, 1), run.stderr
    dom = page.dom(history.as_uri())
    links = re.findall(r'<a class="report" href="([^"]+)">report</a>', dom)
    assert len(links) == 3, dom[-3000:]
    assert reason in dom.replace("&amp;", "&")
    opened = page.dom(links[0])
    assert "zerocal calibration:" in opened
