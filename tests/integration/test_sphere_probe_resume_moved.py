"""A resumed sphere_probe run starts from where the controller reads the robot, not from
the last journaled pose (docs/calibrate.md, "The run folder and resume"): a run cut by an
emergency stop a few contacts in, resumed on a restarted controller that stands at its
start pose (as a resumed --robot sim run finds it), against the real stub on 127.0.0.1."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from controller_stub.network.server import ControllerServer
from controller_stub.world.motion import MotionPlan
from hostpc.calibrate.refusals import RunStopped
from hostpc.methods.base import RunSettings
from tests.integration.conftest import StartStub
from tests.integration.runner_runs import run_on

SCENARIO: dict[str, Any] = {"truth": {"probe_trigger_latency_s": 0.0}}


def _record_moves(server: ControllerServer) -> list[MotionPlan]:
    """Every motion the stub plans from now on (its start, target, IO edges), in order;
    the stub moves as before."""
    plans: list[MotionPlan] = []
    begin = server.sim.begin_move

    def recording(*args: Any, **kwargs: Any) -> MotionPlan:
        plan = begin(*args, **kwargs)
        plans.append(plan)
        return plan

    server.sim.begin_move = recording  # type: ignore[method-assign]
    return plans


@pytest.mark.slow
async def test_resume_starts_from_the_controllers_reading(start_stub: StartStub,
                                                          tmp_path: Path) -> None:
    settings = RunSettings(method="sphere_probe", n_poses=30, n_verify=5, seed=3,
                           cv_folds=0)
    run_dir = tmp_path / "run"
    cut = await start_stub({**SCENARIO, "faults": {"estop_after_moves": 14}})
    with pytest.raises(RunStopped, match="estop"):
        await run_on(cut, run_dir, settings)
    lines = [json.loads(line) for line in (run_dir / "journal.jsonl").read_text().splitlines()]
    samples = [line for line in lines if line.get("event") == "sample"]
    assert 1 <= len(samples) < 30
    last_end = np.asarray(samples[-1]["q_end"], float)

    server = await start_stub(SCENARIO)  # a restarted controller: at its start pose
    reading = np.asarray(server.sim.joint_positions(), float)
    assert float(np.max(np.abs(reading - last_end))) > 0.1  # elsewhere than the journal
    moves = _record_moves(server)
    outcome = await run_on(server, run_dir)

    # the first move starts where the robot is and goes to the next orientation's hover
    # (its clearance checked from there); from the journal's last pose, a contact's start,
    # it went straight to the next contact's start, next to the sphere
    plan = json.loads((run_dir / "probe_plan.json").read_text())
    hovers = np.array([o["q_hover"] for o in plan["orientations"]])
    first = moves[0]
    assert first.io_line is None
    assert np.allclose(first.q_start, reading)
    assert float(np.min(np.max(np.abs(hovers - first.q_target), axis=1))) < 1e-6
    # no free move touches the sphere: the probe input rises on guarded moves only
    touched = [k for k, plan in enumerate(moves)
               if plan.io_line is None and any(edge.value for edge in plan.edges)]
    assert touched == []
    assert outcome.verify is not None and outcome.verify.passed, outcome.verify
    assert outcome.exit_code == 0
