"""hostpc transport against a real controller stub over 127.0.0.1 sockets."""

from __future__ import annotations

import asyncio
import json
import math

import numpy as np
import pytest

from controller_stub.network.server import ControllerServer
from controller_stub.scenario.spec import scenario_from_dict
from controller_stub.world.simulation import Simulation
from hostpc.errors import ConnectionFailed, ControllerError, RequestTimeout
from hostpc.transport import ControllerClient, ControllerRefusedError
from hostpc.transport.io_events import IoEventSubscription
from hostpc.transport.types import IoEdgeEvent
from hostpc.transport.waiting import wait_for_reply
from tests.integration.conftest import BASE_SCENARIO, TOKEN, StartStub

pytestmark = pytest.mark.asyncio

STEP = np.array([0.05, -0.04, 0.03, 0.02, -0.02, 0.05])


def connect(server: ControllerServer, **options: object) -> object:
    host, port = server.address
    options.setdefault("token", TOKEN)
    options.setdefault("timeout", 5.0)
    return ControllerClient.connect(host, port, **options)  # type: ignore[arg-type]


def probe_scenario(lose_edges: list[int] | None = None) -> tuple[dict, np.ndarray, np.ndarray]:
    """A scenario whose reference sphere sits on the tip path from q_start to q_end.

    The tip position half-way along the joint-space path is taken from the simulation
    itself (same seed, so the same hidden truth), so the guarded move must touch it.
    """
    finder = Simulation(scenario_from_dict(BASE_SCENARIO))
    q_start = finder.joint_positions()
    q_end = q_start + np.array([0.3, 0.0, 0.0, 0.0, 0.0, 0.0])
    finder.move_joints((q_start + q_end) / 2, 1.0)
    tip = finder.tip_position()
    overrides = {
        "probe": {"sphere_centre": tip.tolist(), "sphere_centre_error": [0.0, 0.0, 0.0]},
        "faults": {"lose_io_edge_indices": lose_edges or []},
    }
    return overrides, q_start, q_end


async def test_state_move_and_heartbeat(stub: ControllerServer, client: ControllerClient) -> None:
    state = await client.state()
    assert state.robot_name == "ur5e" and state.n_joints == 6
    assert state.authenticated and state.mode == "idle"
    assert state.q_min.shape == (6,) and np.all(state.q_min < state.q_max)
    target = state.q + STEP
    outcome = await client.move_joints(target, speed=0.5)
    assert outcome.completed and outcome.reason is None
    np.testing.assert_allclose(outcome.q, target, atol=1e-12)
    after = await client.state()
    np.testing.assert_allclose(after.q, target, atol=1e-12)
    assert after.time > state.time
    assert await client.heartbeat() == pytest.approx(after.time)


async def test_capture_images_are_uint8_of_scenario_size(client: ControllerClient) -> None:
    state = await client.state()
    left, right, q, t = await client.capture("target")
    assert left.dtype == np.uint8 and right.dtype == np.uint8
    assert left.shape == (256, 320) and right.shape == (256, 320)
    np.testing.assert_allclose(q, state.q)
    assert t == pytest.approx(state.time)
    png_left, png_right, _, _ = await client.capture("target", encoding="png")
    assert png_left.shape == (256, 320) and png_left.dtype == np.uint8
    board_left, _, _, _ = await client.capture("chessboard", view=2)
    assert board_left.shape == (256, 320)


async def test_guarded_move_latches_at_io_edge_and_pushes_event(start_stub: StartStub) -> None:
    overrides, q_start, q_end = probe_scenario()
    server = await start_stub(overrides)
    async with connect(server) as client:
        events = client.subscribe_io()
        outcome = await client.guarded_move(q_end, speed=0.5, io_line=0)
        assert outcome.contact and outcome.q_latched is not None
        # latched somewhere on the path, before the end of travel
        fraction = (outcome.q_latched[0] - q_start[0]) / (q_end[0] - q_start[0])
        assert 0.2 < fraction < 0.8
        np.testing.assert_allclose(outcome.q_latched[1:], q_start[1:], atol=1e-12)
        edge = await events.get(timeout=1.0)
        assert edge.line == 0 and edge.value is True
        np.testing.assert_allclose(edge.q_latched, outcome.q_latched)
        io = await client.read_io()
        assert len(io.digital_inputs) == 8


async def test_guarded_move_without_contact_and_lost_edge(start_stub: StartStub) -> None:
    overrides, q_start, q_end = probe_scenario(lose_edges=[0])
    server = await start_stub(overrides)
    async with connect(server) as client:
        events = client.subscribe_io()
        lost = await client.guarded_move(q_end, speed=0.5, io_line=0)  # edge lost (fault)
        assert not lost.contact and lost.q_latched is None and lost.reason == "no_contact"
        np.testing.assert_allclose(lost.q, q_end)
        pushed = []
        while not events.queue.empty():
            pushed.append(events.queue.get_nowait())
        assert not [e for e in pushed if e.value]  # the lost rising edge is not pushed
        await client.move_joints(q_start + np.array([0, 0.2, 0, 0, 0, 0]), 1.0)
        away = await client.guarded_move(q_start, speed=1.0, io_line=0)  # nowhere near
        assert not away.contact and away.reason == "no_contact"


async def test_set_offsets_and_rollback(stub: ControllerServer, tmp_path) -> None:
    truth_path = tmp_path / "truth.json"
    stub.truth_out = truth_path
    async with connect(stub) as client:
        original = await client.get_offsets()
        new = original + np.radians([0.1, -0.2, 0.05, 0.0, 0.3, -0.1])
        previous, rollback_id = await client.set_offsets(new)
        np.testing.assert_allclose(previous, original)
        np.testing.assert_allclose(await client.get_offsets(), new)
        truth = json.loads(truth_path.read_text())
        np.testing.assert_allclose(truth["zero_offsets"], new)
        restored = await client.rollback(rollback_id)
        np.testing.assert_allclose(restored, original)
        np.testing.assert_allclose(await client.get_offsets(), original)
        np.testing.assert_allclose(json.loads(truth_path.read_text())["zero_offsets"], original)
        with pytest.raises(ControllerRefusedError) as refused:
            await client.rollback("rb-999")
        assert refused.value.code == "unknown_rollback"
        with pytest.raises(ControllerRefusedError) as too_big:
            await client.set_offsets(original + math.radians(10.0))
        assert too_big.value.code == "refused" and too_big.value.reason == "offset_limit"
        np.testing.assert_allclose(await client.get_offsets(), original)


async def test_unauthenticated_writes_are_refused_and_change_nothing(
    stub: ControllerServer, caplog: pytest.LogCaptureFixture
) -> None:
    before_q = stub.sim.joint_positions()
    before_offsets = stub.sim.zero_offsets()
    async with connect(stub, token=None) as reader:
        state = await reader.state()  # reads are allowed before auth
        assert not state.authenticated
        for attempt in (
            reader.move_joints(before_q + STEP, 0.5),
            reader.guarded_move(before_q + STEP, 0.5, 0),
            reader.set_offsets(before_offsets + 0.001),
            reader.rollback("rb-1"),
        ):
            with pytest.raises(ControllerRefusedError) as refused:
                await attempt
            assert refused.value.code == "auth_required"
        assert await reader.heartbeat() >= 0.0  # session still usable
    with caplog.at_level("WARNING", logger="controller_stub.network.server"):
        with pytest.raises(ControllerError, match="auth_failed"):
            async with connect(stub, token="wrong-token"):
                pass
    assert any("authentication failed" in r.getMessage() for r in caplog.records)
    np.testing.assert_array_equal(stub.sim.joint_positions(), before_q)
    np.testing.assert_array_equal(stub.sim.zero_offsets(), before_offsets)


async def test_fault_drop_after_n_requests_resends_only_idempotent(
    start_stub: StartStub,
) -> None:
    server = await start_stub({"faults": {"drop_after_requests": 2}})
    async with connect(server) as client:
        await client.heartbeat()  # request 0
        state = await client.state()  # request 1
        again = await client.state()  # request 2 is dropped: reconnect and re-send
        np.testing.assert_allclose(again.q, state.q)
        assert client.connections_opened == 2
    server = await start_stub({"faults": {"drop_after_requests": 1}})
    async with connect(server) as client:
        q0 = (await client.state()).q  # request 0
        with pytest.raises(ConnectionFailed, match="not re-sent"):
            await client.move_joints(q0 + STEP, 0.5)  # request 1 dropped: never re-sent
        np.testing.assert_array_equal(server.sim.joint_positions(), q0)
        # the caller decides: a new request on a new connection works
        outcome = await client.move_joints(q0 + STEP, 0.5)
        assert outcome.completed


async def test_fault_reply_delay_times_out(start_stub: StartStub) -> None:
    server = await start_stub({"faults": {"reply_delay_s": 0.4}})
    async with connect(server, timeout=0.1) as client:
        with pytest.raises(RequestTimeout, match="heartbeat"):
            await client.heartbeat()
        assert await client.heartbeat(timeout=2.0) >= 0.0  # a patient caller is answered


async def test_fault_refused_move_and_estop(start_stub: StartStub) -> None:
    server = await start_stub({"faults": {"refuse_move_indices": [0], "estop_after_moves": 1}})
    async with connect(server) as client:
        q0 = (await client.state()).q
        with pytest.raises(ControllerRefusedError) as refused:
            await client.move_joints(q0 + STEP, 0.5)
        assert refused.value.reason == "refused_fault"
        assert "refused_fault" in str(refused.value)
        np.testing.assert_array_equal((await client.state()).q, q0)
        assert (await client.move_joints(q0 + STEP, 0.5)).completed
        assert (await client.state()).mode == "estop"
        with pytest.raises(ControllerRefusedError) as stopped:
            await client.move_joints(q0, 0.5)
        assert stopped.value.code == "refused" and stopped.value.reason == "estop"


async def test_joint_limit_refused(client: ControllerClient) -> None:
    state = await client.state()
    with pytest.raises(ControllerRefusedError) as refused:
        await client.move_joints(state.q_max + 0.1, 0.5)
    assert refused.value.reason == "joint_limit"


async def test_abort_and_busy_with_paced_motion(start_stub: StartStub) -> None:
    server = await start_stub({"motion": {"time_scale": 1.0, "max_joint_speed": 0.5}})
    async with connect(server) as mover, connect(server) as other:
        q0 = (await mover.state()).q
        move = asyncio.create_task(mover.move_joints(q0 + 1.0, 1.0, timeout=10.0))  # ~2 s
        await asyncio.sleep(0.2)
        assert (await other.state()).mode == "moving"
        with pytest.raises(ControllerRefusedError) as busy:
            await other.move_joints(q0, 1.0)
        assert busy.value.code == "busy"
        assert await other.abort() is True
        outcome = await asyncio.wait_for(move, 1.0)
        assert not outcome.completed and outcome.reason == "aborted"
        assert (await other.state()).mode == "idle"
        assert await other.abort() is False


async def test_many_clients_at_once(stub: ControllerServer) -> None:
    async def session(index: int) -> int:
        async with connect(stub, token=TOKEN if index % 2 else None) as client:
            for _ in range(20):
                await client.heartbeat()
            if index % 2:
                await client.capture()
            else:  # captures need an authenticated session
                with pytest.raises(ControllerRefusedError, match="auth_required"):
                    await client.capture()
            return (await client.state()).n_joints

    results = await asyncio.gather(*(session(i) for i in range(8)))
    assert results == [6] * 8


async def test_unreachable_controller_raises_connection_failed() -> None:
    with pytest.raises(ConnectionFailed, match="cannot reach controller"):
        async with ControllerClient.connect("127.0.0.1", 1, token=TOKEN, timeout=1.0):
            pass


async def test_modbus_discrete_inputs_mirror_the_simulation(start_stub: StartStub) -> None:
    from pymodbus.client import AsyncModbusTcpClient

    from controller_stub.network.modbus_io import ModbusIoServer

    overrides, q_start, q_end = probe_scenario()
    server = await start_stub(overrides)
    modbus = ModbusIoServer(server.sim, host="127.0.0.1", port=0, writable=True)
    host, port = await modbus.start()
    modbus_client = AsyncModbusTcpClient(host, port=port, timeout=2)
    try:
        assert await modbus_client.connect()
        before = await modbus_client.read_discrete_inputs(0, count=8)
        assert not before.isError()
        assert before.bits[:8] == server.sim.digital_inputs()
        async with connect(server) as client:
            # stop right past the contact so the probe input stays high
            mid = (q_start + q_end) / 2
            await client.move_joints(mid, 1.0)
            assert (await client.read_io()).digital_inputs[0] is True
        after = await modbus_client.read_discrete_inputs(0, count=8)
        assert after.bits[0] is True and after.bits[:8] == server.sim.digital_inputs()
        registers = await modbus_client.read_input_registers(0, count=2)
        assert registers.registers[0] & 1 == 1
        await modbus_client.write_coil(3, True)
        assert server.sim.digital_outputs()[3] is True
        coils = await modbus_client.read_coils(0, count=8)
        assert coils.bits[3] is True
    finally:
        modbus_client.close()
        await modbus.close()


async def test_modbus_is_read_only_by_default(stub: ControllerServer) -> None:
    from pymodbus.client import AsyncModbusTcpClient

    from controller_stub.network.modbus_io import ModbusIoServer

    modbus = ModbusIoServer(stub.sim, host="127.0.0.1", port=0)
    host, port = await modbus.start()
    modbus_client = AsyncModbusTcpClient(host, port=port, timeout=2)
    try:
        assert await modbus_client.connect()
        assert (await modbus_client.write_coil(3, True)).isError()
        assert (await modbus_client.write_register(0, 0xFF)).isError()
        assert stub.sim.digital_outputs() == [False] * 8
        coils = await modbus_client.read_coils(0, count=8)  # reads still work
        assert not coils.isError() and coils.bits[:8] == [False] * 8
    finally:
        modbus_client.close()
        await modbus.close()


async def test_a_cancel_that_comes_with_the_reply_is_not_lost() -> None:
    """A reply and a cancellation (SIGTERM, Ctrl-C: hostpc.cli.termination) in the same loop
    step: the request is cancelled. Python 3.11's asyncio.wait_for returned the reply and lost
    the cancellation, and a SIGTERMed calibrate ran on to push."""
    reply: asyncio.Future[str] = asyncio.get_running_loop().create_future()
    request = asyncio.create_task(wait_for_reply(reply, 5.0))
    await asyncio.sleep(0)  # the request waits for its reply
    reply.set_result("moved")
    request.cancel()
    with pytest.raises(asyncio.CancelledError):
        await request
    # without a cancellation the reply is the result
    reply = asyncio.get_running_loop().create_future()
    request = asyncio.create_task(wait_for_reply(reply, 5.0))
    await asyncio.sleep(0)
    reply.set_result("moved")
    assert await request == "moved"


async def test_a_cancel_that_comes_with_an_io_edge_is_not_lost() -> None:
    """A probe's contact edge and a cancellation in the same loop step (the sphere probe waits
    on `IoEventSubscription.get`): the wait is cancelled; with asyncio.wait_for (3.11) the
    edge was returned and the cancellation lost. Opening a connection and its handshake wait
    the same way (hostpc.transport.waiting)."""
    subscription = IoEventSubscription(8, lambda _: None)
    waiting = asyncio.create_task(subscription.get(5.0))
    await asyncio.sleep(0)
    subscription.deliver(IoEdgeEvent(1, True, 0.0, np.zeros(6)))
    waiting.cancel()
    with pytest.raises(asyncio.CancelledError):
        await waiting
    # a result dropped by a cancellation is released
    released: list[str] = []
    reply: asyncio.Future[str] = asyncio.get_running_loop().create_future()
    request = asyncio.create_task(wait_for_reply(reply, 5.0, released.append))
    await asyncio.sleep(0)
    reply.set_result("connection")
    request.cancel()
    with pytest.raises(asyncio.CancelledError):
        await request
    assert released == ["connection"]


async def test_an_abort_that_times_out_logs_why(start_stub: StartStub,
                                                caplog: pytest.LogCaptureFixture) -> None:
    """A motion's timeout sends an abort; when the abort's reply does not come within its
    own limit either, the warning names the cause (TimeoutError has no text: the line used
    to end with "failed: " and nothing after it)."""
    server = await start_stub({"faults": {"reply_delay_s": 3.0}})
    async with connect(server) as client:
        q0 = (await client.state(timeout=5.0)).q
        with caplog.at_level("WARNING", logger="hostpc.transport.client"), \
                pytest.raises(RequestTimeout, match="abort sent, not confirmed"):
            await client.move_joints(q0 + STEP, 0.5, timeout=0.2)
    assert [r.getMessage() for r in caplog.records if "abort" in r.getMessage()] == [
        "abort of a motion failed: TimeoutError"]


async def test_a_cancel_that_comes_with_the_abort_reply_is_not_lost(
        start_stub: StartStub) -> None:
    """A motion times out, the client sends its abort, and a cancellation (SIGTERM, Ctrl-C)
    comes in the loop step the abort's reply does: the request is cancelled, not turned into
    a RequestTimeout the run would go on from (Python 3.11's asyncio.wait_for returned the
    reply and lost the cancellation, CPython gh-86296)."""
    server = await start_stub({"motion": {"time_scale": 1.0, "max_joint_speed": 0.5}})
    async with connect(server) as client:
        q0 = (await client.state()).q
        move = asyncio.create_task(client.move_joints(q0 + 1.0, 1.0, timeout=0.2))  # ~2 s
        link = client._link
        assert link is not None
        while not link.pending:
            await asyncio.sleep(0)
        (motion,) = link.pending  # the move's request id
        while not any(i != motion for i in link.pending):  # its timeout sends the abort
            assert not move.done()
            await asyncio.sleep(0)
        abort = next(f for i, f in link.pending.items() if i != motion)
        while not abort.done():  # the abort's reply came: cancel before the move resumes
            assert not move.done()
            await asyncio.sleep(0)
        move.cancel()
        with pytest.raises(asyncio.CancelledError):
            await move
        assert abort.result().kind == "aborted"
        assert (await client.state()).mode == "idle"  # the abort stopped the motion
