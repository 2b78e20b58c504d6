"""The unmodified ur_rtde library (1.6) against `controller-stub serve --ur` (a subprocess).

RTDEReceiveInterface, RTDEControlInterface and RTDEIOInterface connect to the stub's UR
personality; what they read and do is checked against the same simulated robot through the
zerocal protocol port. ur_rtde calls run in worker threads (asyncio.to_thread); the stub is
never in this process (ur_rtde's constructors hold the GIL).
"""

from __future__ import annotations

import asyncio
import socket
import struct
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

rtde_receive = pytest.importorskip("rtde_receive")
rtde_control = pytest.importorskip("rtde_control")
rtde_io = pytest.importorskip("rtde_io")

from hostpc.transport import ControllerClient  # noqa: E402
from tests.integration.ur_stub import TOKEN, UrStub, dashboard, ur_stub_process  # noqa: E402

HOST = "127.0.0.1"


@pytest.fixture(scope="module")
def ur_stub(tmp_path_factory: pytest.TempPathFactory) -> Iterator[UrStub]:
    """One UR stub for the module; motions take 0.5 x their simulated time."""
    with ur_stub_process(tmp_path_factory.mktemp("ur_rtde"), {"motion": {"time_scale": 0.5}}) as (
        stub
    ):
        yield stub


@pytest.fixture(scope="module")
def receive(ur_stub: UrStub) -> Iterator[object]:
    interface = rtde_receive.RTDEReceiveInterface(HOST)
    yield interface
    interface.disconnect()


async def zerocal_state(stub: UrStub) -> object:
    async with ControllerClient.connect(stub.host, stub.port, token=TOKEN, timeout=5.0) as client:
        return await client.state()


async def wait_for(predicate: object, timeout: float = 3.0) -> None:
    loop = asyncio.get_running_loop()
    deadline = loop.time() + timeout
    while not predicate():  # type: ignore[operator]
        assert loop.time() < deadline, "condition not met in time"
        await asyncio.sleep(0.01)


async def test_receive_reads_the_simulated_robot(ur_stub: UrStub, receive: object) -> None:
    state = await zerocal_state(ur_stub)
    q = np.array(await asyncio.to_thread(receive.getActualQ))  # type: ignore[attr-defined]
    np.testing.assert_allclose(q, state.q, atol=1e-12)  # type: ignore[attr-defined]
    bits = await asyncio.to_thread(receive.getActualDigitalInputBits)  # type: ignore[attr-defined]
    expected = sum(1 << i for i, v in enumerate(state.digital_inputs) if v)  # type: ignore[attr-defined]
    assert bits == expected
    t0 = receive.getTimestamp()  # type: ignore[attr-defined]
    await wait_for(lambda: receive.getTimestamp() > t0)  # type: ignore[attr-defined]
    assert receive.getRobotMode() == 7  # type: ignore[attr-defined]
    assert receive.getSafetyMode() == 1  # type: ignore[attr-defined]
    assert not receive.isProtectiveStopped()  # type: ignore[attr-defined]
    assert len(receive.getActualTCPPose()) == 6  # type: ignore[attr-defined]
    assert len(receive.getPayloadCog()) == 3  # type: ignore[attr-defined]


async def test_control_movej_moves_the_simulation(ur_stub: UrStub, receive: object) -> None:
    control = await asyncio.to_thread(rtde_control.RTDEControlInterface, HOST)
    try:
        assert await asyncio.to_thread(control.isProgramRunning)
        q0 = np.array(receive.getActualQ())  # type: ignore[attr-defined]
        target = q0 + np.array([0.1, -0.05, 0.08, 0.0, 0.05, -0.1])
        assert await asyncio.to_thread(control.moveJ, target.tolist(), 1.0, 1.4)
        state = await zerocal_state(ur_stub)
        np.testing.assert_allclose(state.q, target, atol=1e-12)  # type: ignore[attr-defined]
        await wait_for(lambda: np.allclose(receive.getActualQ(), target, atol=1e-12))  # type: ignore[attr-defined]

        # asynchronous move, stopped by stopJ: progress reports a running operation
        far = target + np.array([0.6, 0.0, 0.0, 0.0, 0.0, 0.0])
        assert await asyncio.to_thread(control.moveJ, far.tolist(), 0.5, 1.4, True)
        status = await asyncio.to_thread(control.getAsyncOperationProgressEx)
        assert status.isAsyncOperationRunning()
        await asyncio.to_thread(control.stopJ, 2.0)
        status = await asyncio.to_thread(control.getAsyncOperationProgressEx)
        assert not status.isAsyncOperationRunning()
        assert await asyncio.to_thread(control.isSteady)
        assert await asyncio.to_thread(control.stopScript) is None
        await wait_for(lambda: not control.isProgramRunning())
    finally:
        await asyncio.to_thread(control.disconnect)


async def test_stopj_decelerates_at_its_rate_and_the_clock_counts_the_ramp(
    ur_stub: UrStub, receive: object
) -> None:
    """An asynchronous 0.6 rad moveJ at 0.5 rad/s and 1.4 rad/s^2, stopped mid-cruise by
    stopJ(2.0): the arm ramps up (v^2 / 2 x 1.4), cruises, and ramps down at 2.0 rad/s^2
    (v^2 / 2 x 2.0), so over the T seconds of robot time the move took (no settling: it did
    not arrive) it covered d = v T - v^2 / (2 x 1.4) - v^2 / (2 x 2.0). A stop at the cycle
    reached (no ramp down) would cover v^2 / 4 = 0.0625 rad more in the same time."""
    v, up, down = 0.5, 1.4, 2.0
    control = await asyncio.to_thread(rtde_control.RTDEControlInterface, HOST)
    try:
        before = await zerocal_state(ur_stub)
        q0 = np.array(before.q)  # type: ignore[attr-defined]
        far = q0 + np.array([-0.6, 0.0, 0.0, 0.0, 0.0, 0.0])
        assert await asyncio.to_thread(control.moveJ, far.tolist(), v, up, True)
        await asyncio.sleep(0.35)  # time_scale 0.5: cruising from 0.18 s to 0.6 s
        await asyncio.to_thread(control.stopJ, down, False)  # returns at rest
        assert await asyncio.to_thread(control.isSteady)
        after = await zerocal_state(ur_stub)
        q1 = np.array(after.q)  # type: ignore[attr-defined]
        await wait_for(lambda: np.allclose(receive.getActualQ(), q1, atol=1e-12))  # type: ignore[attr-defined]
        spent = after.time - before.time  # type: ignore[attr-defined]
        covered = float(q0[0] - q1[0])
        assert 0.1 < covered < 0.6 - v * v / (2 * down)  # stopped in the cruise, short
        assert covered == pytest.approx(v * spent - v * v / (2 * up) - v * v / (2 * down),
                                        abs=1e-8)  # the clock is a sum of floats
        await asyncio.to_thread(control.moveJ, q0.tolist(), 1.0, 1.4)
    finally:
        await asyncio.to_thread(control.stopScript)
        await asyncio.to_thread(control.disconnect)


async def test_movej_ramps_at_the_acceleration_the_host_sends(
    ur_stub: UrStub, receive: object
) -> None:
    """moveJ 30 deg at 0.5 x 3.14 rad/s and 1.4 rad/s^2 (UR's default, what hostpc's UR
    driver sends): too short to reach its speed, a triangle of 2 sqrt(d / a) = 1.22 s of
    robot time (0.33 s at speed from the first instant); 10 rad/s^2 is capped at the
    scenario's 4.0. No settling: nothing is measured after a move."""
    d = np.radians(30.0)
    control = await asyncio.to_thread(rtde_control.RTDEControlInterface, HOST)
    try:
        for acceleration, ramp in ((1.4, 1.4), (10.0, 4.0)):
            before = await zerocal_state(ur_stub)
            q = np.array(receive.getActualQ())  # type: ignore[attr-defined]
            q[1] += d if acceleration == 1.4 else -d
            assert await asyncio.to_thread(control.moveJ, q.tolist(), 0.5 * 3.14, acceleration)
            after = await zerocal_state(ur_stub)
            spent = after.time - before.time  # type: ignore[attr-defined]
            assert spent == pytest.approx(2 * np.sqrt(d / ramp), rel=1e-9)
    finally:
        await asyncio.to_thread(control.stopScript)
        await asyncio.to_thread(control.disconnect)


async def test_movej_outside_the_limits_is_a_protective_stop(
    ur_stub: UrStub, receive: object
) -> None:
    control = await asyncio.to_thread(rtde_control.RTDEControlInterface, HOST)
    try:
        bad = np.array(receive.getActualQ())  # type: ignore[attr-defined]
        bad[2] = 10.0
        assert not await asyncio.to_thread(control.moveJ, bad.tolist(), 1.0, 1.4)
        await wait_for(receive.isProtectiveStopped)  # type: ignore[attr-defined]
        assert not control.isProgramRunning()
        assert dashboard("unlock protective stop") == "Protective stop releasing"
        await wait_for(lambda: not receive.isProtectiveStopped())  # type: ignore[attr-defined]
        assert await asyncio.to_thread(control.reuploadScript)
        await wait_for(control.isProgramRunning)
        q = np.array(receive.getActualQ())  # type: ignore[attr-defined]
        assert await asyncio.to_thread(control.moveJ, (q + 0.01).tolist(), 1.0, 1.4)
    finally:
        await asyncio.to_thread(control.stopScript)
        await asyncio.to_thread(control.disconnect)


async def test_io_interface_sets_standard_digital_outputs(
    ur_stub: UrStub, receive: object
) -> None:
    io = await asyncio.to_thread(rtde_io.RTDEIOInterface, HOST)
    try:
        assert await asyncio.to_thread(io.setStandardDigitalOut, 3, True)
        await wait_for(lambda: receive.getActualDigitalOutputBits() & 0b1000)  # type: ignore[attr-defined]
        assert receive.getDigitalOutState(3)  # type: ignore[attr-defined]
        state = await zerocal_state(ur_stub)
        assert state.digital_outputs[3]  # type: ignore[attr-defined]
        assert await asyncio.to_thread(io.setStandardDigitalOut, 3, False)
        await wait_for(lambda: not receive.getActualDigitalOutputBits() & 0b1000)  # type: ignore[attr-defined]
    finally:
        await asyncio.to_thread(io.disconnect)


def test_upper_range_registers(ur_stub: UrStub) -> None:
    flags = (
        rtde_control.RTDEControlInterface.FLAG_UPLOAD_SCRIPT
        | rtde_control.RTDEControlInterface.FLAG_UPPER_RANGE_REGISTERS
    )
    control = rtde_control.RTDEControlInterface(HOST, 500.0, flags)
    receive = rtde_receive.RTDEReceiveInterface(HOST, 500.0, [], False, True)
    try:
        q = np.array(receive.getActualQ())
        assert control.moveJ((q - 0.02).tolist(), 1.0, 1.4)
        assert control.isJointsWithinSafetyLimits(q.tolist())
        assert not control.isJointsWithinSafetyLimits([0.0, 0.0, 10.0, 0.0, 0.0, 0.0])
    finally:
        control.stopScript()
        control.disconnect()
        receive.disconnect()


def test_dashboard_answers_like_a_ur(ur_stub: UrStub) -> None:
    assert dashboard("PolyscopeVersion").startswith("URSoftware 5.11")
    assert dashboard("robotmode") == "Robotmode: RUNNING"
    assert dashboard("running") in ("Program running: true", "Program running: false")
    assert dashboard("is in remote control") == "true"
    assert dashboard("get serial number").isdigit()
    assert dashboard("get robot model") == "UR5"
    assert dashboard("stop") == "Stopped"
    assert dashboard("frobnicate").startswith("could not understand")


def test_rtde_refuses_unknown_outputs_and_shared_inputs(ur_stub: UrStub) -> None:
    def package(kind: str, payload: bytes = b"") -> bytes:
        return struct.pack(">HB", 3 + len(payload), ord(kind)) + payload

    def read(sock: socket.socket) -> tuple[int, bytes]:
        header = sock.recv(3, socket.MSG_WAITALL)
        size, kind = struct.unpack(">HB", header)
        return kind, sock.recv(size - 3, socket.MSG_WAITALL) if size > 3 else b""

    with socket.create_connection((HOST, 30004), timeout=5) as a, socket.create_connection(
        (HOST, 30004), timeout=5
    ) as b:
        for sock in (a, b):
            sock.sendall(package("V", struct.pack(">H", 2)))
            assert read(sock) == (ord("V"), b"\x01")
        a.sendall(package("O", struct.pack(">d", 125.0) + b"actual_q,no_such_thing"))
        kind, body = read(a)
        assert kind == ord("O") and body == b"\x00VECTOR6D,NOT_FOUND"
        a.sendall(package("I", b"input_int_register_40"))
        assert read(a) == (ord("I"), b"\x01INT32")
        b.sendall(package("I", b"input_int_register_40"))
        assert read(b) == (ord("I"), b"\x00IN_USE")


@pytest.fixture(autouse=True)
def _stub_alive(request: pytest.FixtureRequest) -> Iterator[None]:
    yield
    stub = request.node.funcargs.get("ur_stub")
    if stub is not None:
        assert stub.process.poll() is None, Path(stub.log).read_text()[-2000:]
