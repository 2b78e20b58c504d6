"""Aborts stop the simulated motion where it was; client motion timeouts abort the robot;
connection errors read well. hostpc transport against a real stub on 127.0.0.1."""

from __future__ import annotations

import asyncio
import math
import socket

import numpy as np
import pytest

from controller_stub.network.server import ControllerServer
from hostpc.errors import ConnectionFailed, RequestTimeout
from hostpc.planning.robot_time import TimeLimits, Waypoints, waypoints_time
from hostpc.transport import ControllerClient
from tests.integration.conftest import TOKEN, StartStub
from tests.integration.test_transport import connect, probe_scenario

pytestmark = pytest.mark.asyncio

SLOW = {"motion": {"time_scale": 1.0, "max_joint_speed": 0.5, "max_joint_acceleration": 2.0}}
"""1 rad takes 2.25 s: 0.25 s ramping up to 0.5 rad/s (0.0625 rad), cruise, 0.25 s down."""
RAMP_S = 0.25
STEP = np.array([1.0, 0.0, 0.0, 0.0, 0.0, 0.0])


def between(q: np.ndarray, q_start: np.ndarray, q_end: np.ndarray) -> float:
    """Fraction of the way from q_start to q_end (joint 1), checking q is on the segment."""
    fraction = float((q[0] - q_start[0]) / (q_end[0] - q_start[0]))
    np.testing.assert_allclose(q, q_start + fraction * (q_end - q_start), atol=1e-12)
    return fraction


async def test_abort_stops_the_robot_where_it_was(start_stub: StartStub) -> None:
    server = await start_stub(SLOW)
    async with connect(server) as mover, connect(server) as other:
        before = await other.state()
        q_end = before.q + STEP
        move = asyncio.create_task(mover.move_joints(q_end, 1.0))
        await asyncio.sleep(0.5)
        moving = await other.state()
        assert moving.mode == "moving"
        assert 0.1 < between(moving.q, before.q, q_end) < 0.5  # not already at the target
        assert await other.abort() is True
        outcome = await asyncio.wait_for(move, 1.0)
        assert not outcome.completed and outcome.reason == "aborted"
        stopped_at = between(outcome.q, before.q, q_end)
        assert 0.15 < stopped_at < 0.5  # 0.5 s and more: past the ramp
        after = await other.state()
        assert after.mode == "idle"
        np.testing.assert_array_equal(after.q, outcome.q)  # the robot stays where it stopped
        assert after.time - before.time == pytest.approx(outcome.duration_s)
        # stopped at cruise where the profile is: half the ramp's time behind a move at
        # speed from the first instant (0.5 rad/s x (t - RAMP_S / 2))
        assert outcome.duration_s == pytest.approx(stopped_at * 2.0 + RAMP_S / 2)


async def test_aborted_guarded_move_reports_no_later_contact(start_stub: StartStub) -> None:
    overrides, q_start, q_end = probe_scenario()  # contact half-way along the path
    server = await start_stub({**overrides, **SLOW})  # 0.3 rad: 0.6 s, contact at ~0.3 s
    async with connect(server) as mover, connect(server) as other:
        events = mover.subscribe_io()
        guarded = asyncio.create_task(mover.guarded_move(q_end, 1.0, io_line=0))
        await asyncio.sleep(0.1)
        assert await other.abort() is True
        outcome = await asyncio.wait_for(guarded, 1.0)
        assert not outcome.contact and outcome.q_latched is None
        assert outcome.reason == "aborted"
        assert between(outcome.q, q_start, q_end) < 0.4
        assert (await other.read_io()).digital_inputs[0] is False
        await asyncio.sleep(0.1)
        assert events.queue.empty()  # no io_edge for a contact after the stop


async def test_motion_timeout_aborts_the_robot(start_stub: StartStub) -> None:
    server = await start_stub(SLOW)
    async with connect(server) as client:
        before = await client.state()
        with pytest.raises(RequestTimeout, match="abort sent: motion stopped"):
            await client.move_joints(before.q + STEP, 1.0, timeout=0.3)
        after = await client.state()
        assert after.mode == "idle"  # the robot does not keep moving unattended
        assert 0.05 < between(after.q, before.q, before.q + STEP) < 0.5


async def test_motions_have_their_own_longer_timeout(start_stub: StartStub) -> None:
    server = await start_stub(SLOW)
    async with connect(server, timeout=0.2) as client:  # fine for requests, short for moves
        assert client.motion_timeout == 120.0
        q0 = (await client.state()).q
        outcome = await client.move_joints(q0 + STEP / 4, 1.0)  # 0.5 s
        assert outcome.completed


async def test_dns_failure_reads_as_such(monkeypatch: pytest.MonkeyPatch) -> None:
    async def no_such_host(*args: object, **kwargs: object) -> None:
        raise socket.gaierror(socket.EAI_NONAME, "Name or service not known")

    monkeypatch.setattr(asyncio, "open_connection", no_such_host)  # no real DNS traffic
    with pytest.raises(ConnectionFailed) as failed:
        async with ControllerClient.connect("robot.invalid", 47800, token=TOKEN, timeout=1.0):
            pass
    message = str(failed.value)
    assert "Name or service not known" in message and "Unknown error" not in message
    assert message.startswith("cannot reach controller at robot.invalid:47800")


async def test_pipelined_requests_beyond_the_in_flight_cap_are_all_answered(
    stub: ControllerServer,
) -> None:
    async with connect(stub) as client:
        replies = await asyncio.gather(*(client.heartbeat() for _ in range(100)))
        assert len(replies) == 100


async def test_a_30_degree_move_ramps_at_the_reported_acceleration(
        start_stub: StartStub) -> None:
    """30 deg at speed 0.5 of 180 deg/s, ramped at 1.4 rad/s^2 (a UR's movej default):
    too short to reach 90 deg/s, so a triangle of 2 sqrt(d / a) = 1.22 s (0.33 s at speed
    from the first instant); the host's prediction (TimeLimits from the state) says the
    same."""
    server = await start_stub({"motion": {"max_joint_acceleration": 1.4, "settle_s": 0.0}})
    d = math.radians(30.0)
    async with connect(server) as client:
        before = await client.state()
        np.testing.assert_array_equal(before.max_joint_acceleration, 1.4)
        outcome = await client.move_joints(before.q + d * np.eye(6)[1], 0.5)
        after = await client.state()
    assert outcome.completed
    expected = 2 * math.sqrt(d / 1.4)
    assert outcome.duration_s == pytest.approx(expected, rel=1e-12)
    assert after.time - before.time == pytest.approx(expected, rel=1e-12)
    limits = TimeLimits.from_extra(
        {"max_joint_speed": before.max_joint_speed,
         "max_joint_acceleration": before.max_joint_acceleration}, 6)
    planned, _, _ = waypoints_time(before.q, Waypoints.plain(after.q[None, :]), 0.5, limits)
    assert planned == pytest.approx(expected, rel=1e-12)


async def test_a_slow_move_is_timed_by_its_prediction(start_stub: StartStub) -> None:
    """Half a radian at SLOW's limits: 1.25 s of controller time, paced 2 wall s per
    controller s (time_scale 2): 2.5 s. A fixed motion timeout (1 s here, 120 s in use)
    would abort it; the default timeout is 3 x the host's prediction of the move from the
    reported limits (3.75 s), so it finishes."""
    server = await start_stub({"motion": {**SLOW["motion"], "time_scale": 2.0}})
    async with connect(server, motion_timeout=1.0) as client:
        q0 = (await client.state()).q
        outcome = await client.move_joints(q0 + STEP / 2, 1.0)
    assert outcome.completed
    assert outcome.duration_s == pytest.approx(0.5 / 0.5 + RAMP_S, rel=1e-9)


async def test_a_via_move_that_a_move_follows_is_not_settled(start_stub: StartStub) -> None:
    """Settling is charged before a measurement, not after every move: a via point, then a
    pose that is captured, then a second captured pose. The host's prediction (settle only
    where a capture follows motion) is the controller time spent (the old stub settled
    0.3 s after the via move too)."""
    server = await start_stub({})
    async with connect(server) as client:
        before = await client.state()
        via = before.q + np.radians([20.0, 0.0, 0.0, 0.0, 0.0, -15.0])
        poses = [before.q + np.radians([20.0, -10.0, 5.0, 0.0, 0.0, -15.0]),
                 before.q + np.radians([25.0, -10.0, 5.0, 0.0, 0.0, -20.0])]
        assert (await client.move_joints(via, 0.5)).completed
        for q in poses:
            assert (await client.move_joints(q, 0.5)).completed
            *_, t = await client.capture()
        after = await client.state()
    limits = TimeLimits.from_extra(
        {"max_joint_speed": before.max_joint_speed,
         "max_joint_acceleration": before.max_joint_acceleration}, 6)
    path = Waypoints(np.array([via, *poses]), np.full(3, np.nan),
                     np.array([False, True, True]), np.zeros(3, bool), 2)
    motion, settle, capture = waypoints_time(before.q, path, 0.5, limits)
    assert settle == pytest.approx(2 * 0.3) and capture == pytest.approx(2 * 0.1)
    assert after.time - before.time == pytest.approx(motion + settle + capture, rel=1e-9)
    assert t - before.time == pytest.approx(motion + settle + 0.1, rel=1e-9)  # exposed
