"""A cell reference keeps the zeros its recording run had: a joint only its frames identify
(J1, J6 with every frame estimated) is restored TO THE REFERENCE, and the run says so
instead of "calibrated" when the recording run did not calibrate that joint (review item 5:
`calibrate --known none`, `reference record`, `calibrate --reference` read "PASS: J1-J6
calibrated and verified" with J6 0.48 deg off in the simulator's truth).

The recording world has J1 and J6 off by 0.2 and 0.5 deg; the recording run cannot see
them (every frame estimated), so the reference's target and tool frames absorb them. The
next run, with the reference, restores J1 and J6 to those zeros, not to the true ones.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from hostpc.cli.main import main
from tests.integration.test_calibrate_reference import calibrate, world

OFF = [math.radians(0.2), 0.0021, -0.0013, 0.0017, -0.0009, math.radians(0.5)]


def test_j1_j6_restored_to_a_reference_that_did_not_calibrate_them_are_not_calibrated(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code, first = calibrate(tmp_path / "run1", world("stereo_target", 3, OFF),
                            "stereo_target", "--require-joints", "all")
    assert code == 7 and first["outcome"]["verdict"] == "JOINTS_MISSING"
    next_command = first["outcome"]["next_command"]
    # never "record a reference from this run" as the way, unless it says what it keeps
    assert f"hostpc reference record --run {tmp_path / 'run1'} " not in next_command
    assert "--known target,tool" in next_command
    assert "keeps this robot's present J1, J6 zeros" in next_command
    reference = tmp_path / "cell_ref.json"
    assert main(["reference", "record", "--run", str(tmp_path / "run1"), "--out",
                 str(reference)]) == 0
    recorded = json.loads(reference.read_text())
    assert recorded["joint_zeros"] == {"1": "as_found", "2": "measured", "3": "measured",
                                       "4": "measured", "5": "measured", "6": "as_found"}
    rig = ("--rig", str(tmp_path / "cell_ref.rig.json"))
    capsys.readouterr()
    code, second = calibrate(tmp_path / "run2", world("stereo_target", 4, OFF),
                             "stereo_target", "--reference", str(reference), *rig)
    stdout = capsys.readouterr().out
    assert code == 0, second["outcome"]["headline"]
    # the truth: J1 and J6 are still off by what the recording run could not see
    errors = second["truth"]["joint_offsets_error_deg"]
    assert abs(errors[0]) > 0.1 and abs(errors[5]) > 0.3, errors
    outcome = second["outcome"]
    source_run = str((tmp_path / "run1").resolve())
    assert outcome["headline"] == (
        f"PASS: J2-J5 calibrated and verified; J1, J6 restored to the cell reference of "
        f"{source_run} (their zeros as at that run, not measured against a surveyed frame)")
    zero_from = {j["joint"]: j["zero_from"] for j in outcome["joints"]}
    assert zero_from[1] == zero_from[6] == {"reference_run": source_run,
                                            "reference_zero": "as_found"}
    assert all(zero_from[n] == "measurements" for n in (2, 3, 4, 5))
    rows = [line for line in stdout.splitlines() if line.startswith(("  J1 ", "  J6 "))]
    assert len(rows) == 2 and all("restored to the cell reference of" in r for r in rows)
    assert "calibrated, verified" not in "".join(rows)

    # a reference written before zerocal kept the record: "unknown", never "calibrated"
    older = {k: v for k, v in recorded.items() if k != "joint_zeros"}
    (tmp_path / "old_ref.json").write_text(json.dumps(older))
    code, third = calibrate(tmp_path / "run3", world("stereo_target", 4, OFF),
                            "stereo_target", "--reference", str(tmp_path / "old_ref.json"),
                            *rig)
    assert code == 0
    assert "J1, J6 restored to the cell reference of" in third["outcome"]["headline"]
    assert "whether that run calibrated them is not recorded" in third["outcome"]["headline"]
    assert {j["joint"]: j["zero_from"] for j in third["outcome"]["joints"]}[1] == {
        "reference_run": source_run, "reference_zero": "unknown"}
    # a reference of run3 carries the unknown on; J2-J5 it measured
    assert main(["reference", "record", "--run", str(tmp_path / "run3"), "--out",
                 str(tmp_path / "ref3.json")]) == 0
    zeros = json.loads((tmp_path / "ref3.json").read_text())["joint_zeros"]
    assert zeros == {"1": "unknown", "2": "measured", "3": "measured", "4": "measured",
                     "5": "measured", "6": "unknown"}
