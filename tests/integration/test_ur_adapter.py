"""hostpc's UR adapter (ur_rtde) against `controller-stub serve --ur` (a subprocess).

Checks the host-side zero offsets (command = wanted - offset, report = measured + offset)
against the simulated robot seen through the zerocal port, captures through the camera
service, and that a move's outcome is a fresh sample at the target.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import AsyncIterator, Iterator

import numpy as np
import pytest

pytest.importorskip("rtde_control")

from hostpc.errors import ControllerError, InputError  # noqa: E402
from hostpc.planning.robot_time import TimeLimits, Waypoints, waypoints_time  # noqa: E402
from hostpc.robots.ur import UrAdapter  # noqa: E402
from hostpc.robots.ur_link import SETTLE_TIMEOUT_S  # noqa: E402
from hostpc.transport import ControllerClient  # noqa: E402
from tests.integration.ur_stub import (  # noqa: E402
    TOKEN,
    UrStub,
    dashboard,
    ur_adapter,
    ur_stub_process,
)


@pytest.fixture(scope="module")
def ur_stub(tmp_path_factory: pytest.TempPathFactory) -> Iterator[UrStub]:
    """One UR stub for the module; motions take 0.3 x their simulated time."""
    directory = tmp_path_factory.mktemp("ur_adapter")
    with ur_stub_process(directory, {"motion": {"time_scale": 0.3}}) as stub:
        yield stub


@pytest.fixture
async def adapter(ur_stub: UrStub) -> AsyncIterator[UrAdapter]:
    async with ur_adapter(ur_stub) as robot:
        yield robot


async def stub_q(stub: UrStub) -> np.ndarray:
    async with ControllerClient.connect(stub.host, stub.port, token=TOKEN, timeout=5.0) as client:
        return (await client.state()).q


async def test_state_reports_the_ur(adapter: UrAdapter, ur_stub: UrStub) -> None:
    state = await adapter.state()
    assert state.robot == "ur5e"
    np.testing.assert_allclose(state.q, await stub_q(ur_stub), atol=1e-12)
    np.testing.assert_array_equal(state.zero_offsets, np.zeros(6))
    assert state.camera["image_width"] == 320
    assert state.extra["offsets_applied_on_host"] is True
    assert len(state.digital_inputs) == 16


async def test_a_move_spends_the_robot_time_the_driver_predicts(
        adapter: UrAdapter, ur_stub: UrStub) -> None:
    """The driver reports what it commands (speed 1 = 3.14 rad/s, moveJ at 1.4 rad/s^2):
    the host's prediction of a move (TimeLimits, the trapezoidal law) is the robot time the
    UR spends (a 120 deg wrist move reaches its speed: d / v + v / a; no settling: nothing
    is measured after it)."""
    state = await adapter.state()
    limits = TimeLimits.from_extra(state.extra, 6)
    np.testing.assert_array_equal(limits.joint_acceleration, 1.4)
    np.testing.assert_array_equal(limits.joint_speed, 3.14)
    target = state.q + np.radians([20.0, -10.0, 15.0, 0.0, 5.0, 120.0])
    async with ControllerClient.connect(ur_stub.host, ur_stub.port, token=TOKEN,
                                        timeout=5.0) as client:
        t0 = (await client.state()).time
        assert (await adapter.move_joints(target, 0.5)).completed
        spent = (await client.state()).time - t0
    motion, _, _ = waypoints_time(state.q, Waypoints.plain(target[None, :]), 0.5, limits)
    v, d = 0.5 * 3.14, np.radians(120.0)
    assert motion == pytest.approx(d / v + v / 1.4, rel=1e-12)
    assert spent == pytest.approx(motion, rel=1e-9)
    await adapter.move_joints(state.q, 0.5)


async def test_host_offsets_command_and_report(adapter: UrAdapter, ur_stub: UrStub) -> None:
    offsets = np.array([0.01, -0.004, 0.003, 0.0, -0.002, 0.005])
    previous, rollback_id = await adapter.set_offsets(offsets)
    np.testing.assert_array_equal(previous, np.zeros(6))

    start = (await adapter.state()).q
    np.testing.assert_allclose(start, await stub_q(ur_stub) + offsets, atol=1e-12)

    wanted = start + np.array([0.2, -0.1, 0.15, 0.1, -0.1, 0.2])
    outcome = await adapter.move_joints(wanted, 0.5)
    assert outcome.completed
    # the robot was commanded wanted - offset ...
    np.testing.assert_allclose(await stub_q(ur_stub), wanted - offsets, atol=1e-12)
    # ... and the outcome is a fresh sample at the target, reported with the offset
    np.testing.assert_allclose(outcome.q, wanted, atol=1e-9)

    capture = await adapter.capture("target")
    assert capture.left.shape == (256, 320) and capture.right.shape == (256, 320)
    np.testing.assert_allclose(capture.q, wanted, atol=1e-12)

    replaced = await adapter.rollback(rollback_id)
    np.testing.assert_array_equal(replaced, offsets)
    np.testing.assert_array_equal(await adapter.get_offsets(), np.zeros(6))
    np.testing.assert_allclose((await adapter.state()).q, wanted - offsets, atol=1e-12)


async def test_refusals(adapter: UrAdapter) -> None:
    with pytest.raises(ControllerError, match="exceeds the limit"):
        await adapter.set_offsets(np.array([0.5, 0, 0, 0, 0, 0]))
    with pytest.raises(InputError):
        await adapter.move_joints(np.zeros(5), 0.5)
    with pytest.raises(ControllerError, match="unknown rollback"):
        await adapter.rollback("nope")


async def test_move_outside_limits_fails_cleanly(adapter: UrAdapter) -> None:
    q = (await adapter.state()).q.copy()
    q[2] = 10.0
    outcome = await adapter.move_joints(q, 0.5)
    assert not outcome.completed
    assert outcome.reason in ("protective_stop", "control_script_stopped")
    assert dashboard("unlock protective stop") == "Protective stop releasing"


async def test_a_guarded_approach_the_controller_stops_says_why(adapter: UrAdapter) -> None:
    """A guarded approach that would miss the sphere, ended about 1 s in by the dashboard's
    `stop` (the program ends, as on a protective stop): the outcome says why
    (control_script_stopped) and where the arm stopped, at once. The old driver waited
    SETTLE_TIMEOUT_S for an arm that never reached the target and reported no_contact."""
    q0 = (await adapter.state()).q
    target = q0 + np.radians([0.0, 0.0, 0.0, 0.0, 0.0, 90.0])  # 10 s at 0.157 rad/s, x 0.3
    approach = asyncio.ensure_future(adapter.guarded_move(target, 0.05, 0))
    await asyncio.sleep(1.0)
    assert not approach.done()
    assert await asyncio.to_thread(dashboard, "stop") == "Stopped"
    stopped = time.monotonic()
    outcome = await approach
    answered = time.monotonic() - stopped
    assert not outcome.contact
    assert outcome.reason == "control_script_stopped"
    assert answered < SETTLE_TIMEOUT_S, answered
    np.testing.assert_allclose(outcome.q, (await adapter.state()).q, atol=1e-6)
    assert float(np.degrees(np.max(np.abs(target - outcome.q)))) > 30.0
