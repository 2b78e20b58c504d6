"""A UR run archived: the UR keeps no zero offsets, so its push is applied on the host for
this session only. result.json, the archive (`hostpc history --json`) and the station's
registers say so, never "pushed". Real `controller-stub serve --ur --port 0` (its UR ports
are fixed: run under `flock /tmp/zerocal-ur.lock`), real ur_rtde client, real SQLite
archive."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import pytest

pytest.importorskip("rtde_control")

from hostpc.archive import open_archive  # noqa: E402
from hostpc.robots.simulator import default_sim_scenario  # noqa: E402
from hostpc.station import registers as reg  # noqa: E402
from hostpc.station.service import archived_outcome  # noqa: E402
from tests.integration.ur_stub import ur_stub_process  # noqa: E402
from tests.station.conftest import REPO, hostpc_command  # noqa: E402


def test_a_ur_run_is_archived_applied_on_the_host_not_pushed(tmp_path: Path) -> None:
    """Review F6: the run printed "controller: zero offsets unchanged ... applied on the
    host" and its outcome said not pushed, yet result.json's push status and the archive's
    push_status said "pushed"."""
    db = f"sqlite:///{tmp_path / 'archive.db'}"
    run_dir = tmp_path / "run"
    with ur_stub_process(tmp_path / "stub", base=default_sim_scenario(0.0)) as stub:
        run = subprocess.run(
            hostpc_command("calibrate", "--robot", f"{stub.host}:{stub.port}", "--driver",
                           "ur", "--known", "target", "--seed", "0", "--poses", "12",
                           "--verify-poses", "4", "--robot-serial", "UR-1", "--db", db,
                           "--out", str(run_dir), "--no-report"),
            cwd=REPO, capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stdout[-2000:] + run.stderr[-2000:]
    assert "applied on the host for this session only" in run.stdout

    result = json.loads((run_dir / "result.json").read_text())
    assert result["outcome"]["pushed"] is False and result["outcome"]["verdict"] == "PASS"
    assert result["push"]["status"] == "applied_on_host"
    assert result["push"]["on_controller"] is False
    summary = (run_dir / "summary.txt").read_text()
    assert "push: applied on the host for this session only (UR has no writable zero " \
        "offsets)" in summary

    history = subprocess.run(hostpc_command("history", "--db", db, "--json"), cwd=REPO,
                             capture_output=True, text=True, timeout=120)
    assert history.returncode == 0, history.stderr
    (row,) = json.loads(history.stdout)["runs"]
    assert (row["verdict"], row["push_status"]) == ("PASS", "applied_on_host")

    with open_archive(db, create=False) as archive:
        (stored_row,) = archive.runs()
        stored = archive.run(stored_row.id)
    assert stored.result is not None
    assert stored.result.push.stated_status == "applied_on_host"  # read back as written
    registers = reg.outcome_registers(archived_outcome(stored))
    assert reg.State(registers[reg.STATE]) == reg.State.PASS
    assert not registers[reg.OUTCOME_FLAGS] & reg.FLAG_PUSHED
    assert registers[reg.OUTCOME_FLAGS] & reg.FLAG_VERIFIED
    assert registers[reg.JOINTS_PUSHED] == 0
