"""End to end: `hostpc calibrate --driver ur --method stereo_target` against the stub's UR
personality recovers the injected zero errors as the zerocal protocol driver does.

Both runs use the same simulated world (the `--robot sim` default scenario, motions without
wall time) on a fresh `controller-stub serve --ur` subprocess each, the same planning seed,
and the target declared known. The UR run drives the robot with ur_rtde (moveJ, getActualQ)
and takes its images from the stub's camera service (`--robot 127.0.0.1:PORT`: for the UR
driver the port is the camera service's); its push sets the adapter's host-side offsets,
so its verification runs through them.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

pytest.importorskip("rtde_control")

from hostpc.robots.simulator import default_sim_scenario  # noqa: E402
from tests.integration.ur_stub import ur_stub_process  # noqa: E402


def _calibrate(tmp_path: Path, name: str, driver: str) -> tuple[dict[str, Any], np.ndarray]:
    with ur_stub_process(tmp_path / f"{name}-stub", base=default_sim_scenario(0.0)) as stub:
        run = subprocess.run(
            [sys.executable, "-m", "hostpc.cli.main", "calibrate",
             "--robot", f"{stub.host}:{stub.port}", "--driver", driver,
             "--method", "stereo_target", "--known", "target", "--seed", "0",
             "--out", str(tmp_path / name), "--json", "--no-report"],
            capture_output=True, text=True, timeout=600,
        )
        assert run.returncode == 0, run.stderr[-3000:]
        truth = json.loads(stub.truth_out.read_text())
    return json.loads(run.stdout), np.degrees(truth["zero_errors_initial"])


@pytest.mark.slow
def test_ur_driver_recovers_the_offsets_like_the_protocol_driver(tmp_path: Path) -> None:
    reference, truth = _calibrate(tmp_path, "zerocal", "zerocal")
    document, truth_ur = _calibrate(tmp_path, "ur", "ur")
    np.testing.assert_allclose(truth_ur, truth)
    assert document["robot"]["driver"] == "ur"
    assert document["push"]["status"] == "applied_on_host"
    assert document["verify"]["passed"]

    rows = document["offsets"]["joints"]
    reference_rows = reference["offsets"]["joints"]
    for row, reference_row, true_deg in zip(rows, reference_rows, truth, strict=True):
        if reference_row["correction_deg"] is None:
            assert row["correction_deg"] is None  # unidentifiable with both drivers
            continue
        assert row["correction_deg"] == pytest.approx(reference_row["correction_deg"], abs=1e-3)
        assert abs(row["correction_deg"] - true_deg) <= max(4 * row["sigma_deg"], 2e-3)

    _check_ur_exports(tmp_path / "ur", document)


def _check_ur_exports(run_dir: Path, document: dict[str, Any]) -> None:
    """A UR push is host-side only: the run folder carries the offsets as the ur_description
    calibration yaml, URDF joints and URScript, the summary says so, rollback refuses."""
    import xml.etree.ElementTree as ET

    import yaml

    from hostpc.kinematics import get_robot
    from hostpc.robots.ur_export import UR_KINEMATICS_KEYS, joint_origins

    push = document["push"]
    assert push["on_controller"] is False
    new = np.radians([row["new_deg"] for row in document["offsets"]["joints"]])
    assert np.any(new != 0.0)
    origins, _ = joint_origins(get_robot(document["robot"]["name"]), new)

    paths = {kind: Path(path) for kind, path in push["exports"].items()}
    assert paths["yaml"] == run_dir / "ur_calibration.yaml"
    kinematics = yaml.safe_load(paths["yaml"].read_text())["kinematics"]
    for key, origin in zip(UR_KINEMATICS_KEYS, origins, strict=True):
        got = kinematics[key]
        np.testing.assert_allclose([got["x"], got["y"], got["z"]], origin.xyz, atol=1e-12)
        np.testing.assert_allclose([got["roll"], got["pitch"], got["yaw"]], origin.rpy,
                                   atol=1e-12)
    joints = ET.parse(paths["urdf"]).getroot().findall("joint")
    assert len(joints) == 6
    for joint, origin in zip(joints, origins, strict=True):
        rpy = [float(v) for v in joint.find("origin").attrib["rpy"].split()]  # type: ignore[union-attr]
        np.testing.assert_allclose(rpy, origin.rpy, atol=1e-12)
    script = paths["urscript"].read_text()
    assert f"{new[1]:.9g}" in script and "def zerocal_command" in script

    summary = (run_dir / "summary.txt").read_text()
    assert ("push: applied on the host for this session only (UR has no writable zero "
            f"offsets); load {paths['yaml']} in your UR/ROS setup") in summary
    rollback = subprocess.run(
        [sys.executable, "-m", "hostpc.cli.main", "rollback", "--run", str(run_dir)],
        capture_output=True, text=True, timeout=60)
    assert rollback.returncode == 2
    assert rollback.stdout == "" and len(rollback.stderr.strip().splitlines()) == 1
    assert "not applicable to a UR" in rollback.stderr


def test_a_ur_push_is_applied_on_the_host_and_every_view_says_so(tmp_path: Path) -> None:
    """Review item 6: a UR run read "controller: new offsets, verified" and every row
    "pushed yes" while the UR's zeros never changed: the outcome, the rows, result.json
    and the station's pushed flag say the offsets are applied on the host only."""
    document, _ = _calibrate(tmp_path, "ur", "ur")
    outcome = document["outcome"]
    run_dir = tmp_path / "ur"
    assert outcome["verdict"] == "PASS" and outcome["exit_code"] == 0
    assert outcome["pushed"] is False and outcome["applied_on_host"] is True
    assert outcome["controller"] == (
        "zero offsets unchanged: the new ones are applied on the host for this session "
        f"only (verified); to keep them: load {run_dir}/ur_calibration.yaml in the robot's "
        f"UR/ROS setup (or {run_dir}/ur_offsets.script in its program; docs/calibrate.md, "
        "A UR)")
    assert "applied on the host for this session only: the controller's zero offsets are " \
        "unchanged" in outcome["headline"]
    calibrated = [j for j in outcome["joints"] if j["status"] == "calibrated"]
    assert calibrated and all(j["pushed"] is False and j["applied_on_host"] is True
                              and j["verified"] is True for j in calibrated)
    rows = [r for r in document["offsets"]["joints"] if r["correction_deg"] is not None]
    assert rows and not any(r["pushed"] for r in rows)
    assert all(r["note"].startswith("applied on the host for this session only") for r in rows)
    summary = (run_dir / "summary.txt").read_text()
    assert "controller: new offsets" not in summary and "  yes  " not in summary
    # the station's flags: not pushed (the controller holds nothing new), verified
    from hostpc.archive.records import outcome_of
    from hostpc.calibrate.run_result import RunResult
    from hostpc.station.registers import FLAG_PUSHED, FLAG_VERIFIED, outcome_bits

    figures = outcome_of(RunResult.from_dict(document))
    assert figures is not None and figures.pushed is False and figures.verified is True
    flags = outcome_bits(figures, "none", ()).outcome_flags
    assert not flags & FLAG_PUSHED and flags & FLAG_VERIFIED
