"""Robot time on the UR personality is the simulated controller's (issue 28, review findings 4
and 5), through the real ur_rtde library against `controller-stub serve --ur` (a subprocess).

The RTDE timestamp is the controller's uptime (`controller_stub/ur/uptime.py`): the wall time
that passes plus every simulated second of motion, settling and capture the simulation
charges beyond it. At time_scale 0 a move takes no wall time, so the old timestamp (the wall
time of the controller cycles only) reported 0.6 s for a run that plans 20.4 s.

A UR does not settle before a moveJ: the UR driver waits until the arm has stood still
`settle_s` on the controller's clock before a guarded approach (`UrLink.settle`), whether the
approach then touches or misses, as the host's prediction charges it
(`hostpc.planning.robot_time`: a measurement that follows motion settles first). The old stub
charged that settle and wound it back when the approach missed: it was charged nowhere.
"""

from __future__ import annotations

import asyncio
import json
import subprocess
import time
from collections.abc import AsyncIterator, Iterator
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("rtde_control")

from hostpc.planning.robot_time import TimeLimits, Waypoints, waypoints_time  # noqa: E402
from hostpc.robots.simulator import default_sim_scenario  # noqa: E402
from hostpc.robots.ur import UrAdapter  # noqa: E402
from hostpc.robots.ur_link import SETTLE_S  # noqa: E402
from tests.integration.test_calibrate_sim import sim_scenario, truth_rig_file  # noqa: E402
from tests.integration.test_interrupt_motion import ENV, REPO  # noqa: E402
from tests.integration.ur_stub import (  # noqa: E402
    UrStub,
    calibrate_command,
    ur_adapter,
    ur_stub_process,
)


def test_a_ur_run_at_time_scale_0_spends_the_robot_time_it_plans(tmp_path: Path) -> None:
    """8 poses of the known target (the rig given, no verification) at time_scale 0: the
    robot time spent is the plan's (motion, settling, captures), plus at most the wall time
    the run took (the controller's uptime runs while the host computes; time the arm
    stood still then counts toward its settling)."""
    rig = truth_rig_file(sim_scenario(), tmp_path / "rig.json")
    with ur_stub_process(tmp_path / "stub", base=default_sim_scenario(0.0)) as stub:
        started = time.monotonic()
        run = subprocess.run(calibrate_command(stub, rig, tmp_path / "run", 1.0, "--json"),
                             cwd=REPO, env=ENV, capture_output=True, text=True, timeout=600)
        wall = time.monotonic() - started
    assert run.returncode == 0, run.stderr[-3000:]
    document = json.loads(run.stdout)
    planned = document["plan"]["predicted_robot_time_s"]["total"]
    spent = document["robot_time_s"]
    assert spent["clock"] == "controller"
    assert planned > 10.0  # 8 poses' moves, settling and captures
    assert planned * (1.0 - 1e-3) <= spent["measure"] <= planned + wall, (planned, spent, wall)


@pytest.fixture(scope="module")
def ur_stub(tmp_path_factory: pytest.TempPathFactory) -> Iterator[UrStub]:
    """One UR stub at time_scale 0 (plain moves take no wall time; a watched moveJ is paced
    in real time)."""
    with ur_stub_process(tmp_path_factory.mktemp("ur_robot_time"),
                         {"motion": {"time_scale": 0.0}}) as stub:
        yield stub


@pytest.fixture
async def adapter(ur_stub: UrStub) -> AsyncIterator[UrAdapter]:
    async with ur_adapter(ur_stub) as robot:
        yield robot


async def _clock(adapter: UrAdapter) -> float:
    time_s = (await adapter.state()).controller_time
    assert time_s is not None
    return time_s


async def test_a_missed_guarded_approach_is_charged_its_settle(adapter: UrAdapter) -> None:
    """A plain move, then a guarded approach that misses the sphere: the controller's clock
    spends the approach's motion and, before it, the settle (the arm stood still SETTLE_S
    since the plain move ended); after the host stood still longer than that, the next
    approach does not wait again."""
    state = await adapter.state()
    limits = TimeLimits.from_extra(state.extra, 6)
    assert limits.settle_s == SETTLE_S
    q0 = state.q
    q1 = q0 + np.radians([0.0, 0.0, 0.0, 0.0, 0.0, 40.0])  # a wrist turn, far from the sphere
    q2 = q0 + np.radians([0.0, 0.0, 0.0, 0.0, 0.0, 80.0])
    assert (await adapter.move_joints(q1, 1.0)).completed
    t0 = await _clock(adapter)
    missed = await adapter.guarded_move(q2, 0.2, 0)
    spent = await _clock(adapter) - t0
    assert not missed.contact and missed.reason == "no_contact"
    approach, _, _ = waypoints_time(q1, Waypoints.plain(q2[None, :]), 0.2, limits)
    assert approach > 0.5
    # the settle, then the approach paced in real time, then the host's reads (ms)
    assert approach + SETTLE_S - 0.1 <= spent <= approach + SETTLE_S + 0.5, (spent, approach)

    await asyncio.sleep(SETTLE_S + 0.2)  # the arm stands still: it settles meanwhile
    t0 = await _clock(adapter)
    assert await adapter.link.settle() == 0.0
    missed = await adapter.guarded_move(q1, 0.2, 0)
    spent = await _clock(adapter) - t0
    assert missed.reason == "no_contact"
    assert approach - 0.01 <= spent <= approach + SETTLE_S - 0.05, (spent, approach)
    assert (await adapter.move_joints(q0, 1.0)).completed


async def test_a_restarted_controller_does_not_hold_up_the_settle(adapter: UrAdapter) -> None:
    """A controller restarted behind a live link: its uptime begins again below the rest
    the link noted before (here: a rest noted 1000 s ahead of the uptime). The settle counts
    the rest from the first lower sample (SETTLE_S on the new clock); the old settle waited
    out the old uptime (1000 s)."""
    assert (await adapter.move_joints((await adapter.state()).q, 1.0)).completed
    rest = adapter.link.rest_since
    assert rest is not None
    adapter.link.rest_since = rest + 1000.0
    waited = await asyncio.wait_for(adapter.link.settle(), 10.0)
    assert SETTLE_S - 0.01 <= waited <= SETTLE_S + 0.5, waited


async def test_an_interrupt_while_settling_says_the_arm_is_at_rest(adapter: UrAdapter) -> None:
    """A guarded approach cancelled (Ctrl-C, SIGTERM) while it waits for the arm to settle:
    the cancellation carries a note saying the arm stood still (no stop sent), as one
    cancelled mid-move says where stopJ stopped it; the old driver added no note."""
    q0 = (await adapter.state()).q
    assert (await adapter.move_joints(q0, 1.0)).completed  # the settle starts now
    approach = asyncio.ensure_future(
        adapter.guarded_move(q0 + np.radians([0.0, 0.0, 0.0, 0.0, 0.0, 40.0]), 0.2, 0))
    await asyncio.sleep(0.3 * SETTLE_S)
    assert not approach.done()
    approach.cancel()
    with pytest.raises(asyncio.CancelledError) as raised:
        await approach
    assert getattr(raised.value, "__notes__", []) == [
        "guarded_move interrupted while settling: arm at rest, no stop needed"]
    np.testing.assert_allclose((await adapter.state()).q, q0, atol=1e-9)

