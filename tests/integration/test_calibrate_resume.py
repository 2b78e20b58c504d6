"""A calibration cut by a dropped connection and resumed gives the uncut run's dataset.

The stub fault `drop_after_requests` drops the link on a motion request (never re-sent by
the client), so `hostpc calibrate` stops with exit code 3 and a one-line message; the
journal keeps every pose measured so far, and `hostpc calibrate --resume DIR` finishes the
run. Compared with an uncut run of the same scenario and seed, sample for sample.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from hostpc.robots.simulator import SimulatedController
from tests.integration.test_calibrate_sim import TOKEN, run_cli, sim_scenario, truth_rig_file

POSES = 16
# requests: get_state, get_offsets, the robot-time clock reading after the rig, then
# (move, capture, clock reading) per pose: index 3 + 3k is the move to pose k; the drop
# makes that move fail (not executed, not re-sent)
DROP_AT_POSE = 7
DROP_INDEX = 3 + 3 * DROP_AT_POSE


def _calibrate(capsys: pytest.CaptureFixture[str], sim: SimulatedController, rig: Path,
               out: Path) -> tuple[int, str, str]:
    address = f"{sim.address.host}:{sim.address.port}"
    return run_cli(capsys, "calibrate", "--robot", address, "--token", TOKEN, "--rig",
                   str(rig), "--poses", str(POSES), "--verify-poses", "4", "--seed", "3",
                   "--no-push", "--no-report", "--out", str(out))


def _samples(run: Path) -> list[dict[str, object]]:
    samples: list[dict[str, object]] = json.loads((run / "dataset.json").read_text())["samples"]
    return samples


@pytest.mark.slow
def test_cut_and_resumed_run_equals_uncut_run(tmp_path: Path,
                                              capsys: pytest.CaptureFixture[str]) -> None:
    rig = truth_rig_file(sim_scenario(), tmp_path / "rig.json")
    cut = tmp_path / "cut"
    with SimulatedController(sim_scenario(drop_after_requests=DROP_INDEX),
                             tmp_path / "stub-cut") as sim:
        code, _, stderr = _calibrate(capsys, sim, rig, cut)
        assert code == 3, stderr
        last = stderr.strip().splitlines()[-1]  # progress lines above, then one error line
        assert last.startswith("hostpc calibrate: error: ")
        assert "not re-sent" in last and f"--resume {cut}" in last
        lines = [json.loads(line) for line in (cut / "journal.jsonl").read_text().splitlines()]
        # every pose measured before the cut is journaled, each with its robot time
        assert [e["event"] for e in lines] == ["sample", "robot_time"] * DROP_AT_POSE
        assert not (cut / "dataset.json").exists()
        code, stdout, stderr = run_cli(capsys, "calibrate", "--resume", str(cut))
        assert code == 0, stderr
        assert "resuming" in stderr
    uncut = tmp_path / "uncut"
    with SimulatedController(sim_scenario(), tmp_path / "stub-uncut") as sim:
        code, _, stderr = _calibrate(capsys, sim, rig, uncut)
        assert code == 0, stderr
    resumed_samples, uncut_samples = _samples(cut), _samples(uncut)
    assert len(resumed_samples) == len(uncut_samples) == POSES
    for index, (a, b) in enumerate(zip(resumed_samples, uncut_samples, strict=True)):
        assert a == b, f"sample {index} differs"
    journal = [json.loads(line) for line in (cut / "journal.jsonl").read_text().splitlines()]
    keys = [(r["phase"], r["index"]) for r in journal if r["event"] == "sample"]
    assert len(keys) == len(set(keys)) == POSES + 4  # nothing repeated, nothing lost
    assert json.loads((cut / "run.json").read_text())["plan"] == json.loads(
        (uncut / "run.json").read_text())["plan"]
