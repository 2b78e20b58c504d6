"""A measurement kind with its OWN instrument, added from one folder
(tests/kinds_example/string_pot: its descriptor, file face and model, method and simulated
sensor), runs ``hostpc fit``, ``hostpc diagnose --ladder`` and ``hostpc calibrate --robot
sim`` end to end, and ``--record`` / ``--replay`` too. No existing file knows it: the host
loads the folder with ``--plugin``, the stub (a real ``controller-stub serve`` subprocess on
port 0) loads its ``sim_sensor.py`` with ``--sensor-plugin``, and the instrument travels
through the generic ``sensor_read`` call, whose broken inputs are refused here with the
protocol's error codes over real sockets.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from collections.abc import AsyncIterator
from pathlib import Path

import numpy as np
import pytest

from controller_stub.network.server import ControllerServer
from controller_stub.scenario.spec import scenario_from_dict
from hostpc.errors import ControllerError
from hostpc.model.measurements import measurement_models
from hostpc.sensors.recording import read_header
from hostpc.transport import ControllerClient, ControllerRefusedError
from protocol import messages as m
from protocol.measurement_messages import MAX_SENSOR_NODES, SensorRead
from tests.controller_stub.test_server import RawClient
from tests.hostpc.measurement_contract import check_model
from tests.integration.test_calibrate_sim import run_cli
from tests.integration.test_example_kind import synthetic_file

KIND = str(Path(__file__).resolve().parents[1] / "kinds_example" / "string_pot")
TRUTH = {"joint_offsets.q1": -0.0009, "joint_offsets.q2": 0.0012, "joint_offsets.q3": -0.0008,
         "joint_offsets.q4": 0.0005, "joint_offsets.q5": -0.0006, "joint_offsets.q6": 0.0007}
SIGMA = 1e-5
"""The averaged reading's noise (m) of the synthetic datasets, as the example's."""
TOLERANCE_DEG = 0.01
"""Largest error of a recovered joint offset in the simulated run (measured: 0.0015 deg)."""
TOKEN = "server-test"  # tests.controller_stub.test_server's RawClient speaks it


def string_pot_file(tmp_path: Path) -> Path:
    return synthetic_file(tmp_path, KIND, "string_pot", "length", SIGMA, TRUTH)


def test_the_folder_kind_keeps_the_measurement_contract(tmp_path: Path) -> None:
    models = measurement_models([KIND])
    assert "string_pot" in models and "string_pot" not in measurement_models()
    check_model(models["string_pot"], tmp_path, plugins=[KIND])


def test_fit_of_the_folder_kind(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code, stdout, stderr = run_cli(capsys, "fit", str(string_pot_file(tmp_path)), "--plugin",
                                   KIND, "--json")
    assert code == 0, stderr
    result = json.loads(stdout)
    assert result["method"] == "string_pot" and result["converged"]
    for name, true in TRUTH.items():
        estimate = result["parameters"][name]
        assert abs(estimate["value"] - true) < 5 * estimate["std"] + 1e-6, name


def test_diagnose_ladder_of_the_folder_kind(tmp_path: Path,
                                            capsys: pytest.CaptureFixture[str]) -> None:
    code, stdout, stderr = run_cli(capsys, "diagnose", "--ladder", str(string_pot_file(tmp_path)),
                                   "--plugin", KIND)
    assert code == 0, stderr
    assert "ladder:" in stdout and "adequate" in stdout


def test_calibrate_sim_with_its_own_instrument_recorded_and_replayed(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "run"
    code, stdout, stderr = run_cli(capsys, "calibrate", "--robot", "sim", "--plugin", KIND,
                                   "--method", "string_pot", "--poses", "20",
                                   "--verify-poses", "4", "--out", str(out), "--json",
                                   "--no-report", "--record")
    assert code == 0, stderr
    document = json.loads(stdout)
    assert document["method"] == "string_pot" and document["known"] == ["tool", "anchor"]
    errors = document["truth"]["joint_offsets_error_deg"]  # fitted - injected, 6 joints
    assert len(errors) == 6 and all(e is not None and abs(e) <= TOLERANCE_DEG
                                    for e in errors), errors
    assert document["push"]["status"] == "pushed" and document["verify"]["passed"] is True
    planned = document["plan"]["predicted_robot_time_s"]  # a reading costs capture_s
    spent = document["robot_time_s"]
    assert spent["measure"] + spent["verify"] == pytest.approx(planned["total"], rel=0.01)
    truth = json.loads((out / "sim" / "truth.json").read_text())
    assert set(truth["sensors"]) == {"string_pot"}  # the stub simulated it from the folder
    tape = [json.loads(line) for line in
            (out / "recording" / "tape.jsonl").read_text().splitlines()]
    reads = [e for e in tape if e["call"] == "sensor_read"]
    assert len(reads) >= 1 + 20 + 4 and reads[0]["args"]["request"] == {"what": "describe"}
    header = read_header(out / "recording")  # recording.json read -> typed -> written
    assert header.sensor_read and header.settings is not None
    assert (json.dumps(header.to_json(), indent=2) + "\n"
            == (out / "recording" / "recording.json").read_text())

    replayed = tmp_path / "replayed"
    code, _, stderr = run_cli(capsys, "calibrate", "--replay", str(out / "recording"),
                              "--out", str(replayed), "--no-report")
    assert code == 0, stderr
    assert (replayed / "dataset.json").read_bytes() == (out / "dataset.json").read_bytes()


def test_the_stub_refuses_a_sensor_plugin_that_imports_hostpc(tmp_path: Path) -> None:
    (tmp_path / "sim_sensor.py").write_text(
        "import hostpc.kinematics\n\nSIM_SENSORS = {'cheat': lambda setup: None}\n")
    done = subprocess.run(
        [sys.executable, "-m", "controller_stub", "serve", "--port", "0",
         "--sensor-plugin", str(tmp_path)],
        capture_output=True, text=True, timeout=60, cwd=Path(__file__).resolve().parents[2])
    assert done.returncode == 2 and "imports hostpc" in done.stderr, done.stderr
    assert "listening on" not in done.stdout


def test_an_installed_package_publishes_the_sensor_by_entry_point(tmp_path: Path) -> None:
    """The other way in: an installed distribution's entry point (group
    zerocal.sim_sensors), found by importlib.metadata in a fresh process; the same name
    from a folder as well is refused."""
    info = tmp_path / "string_pot_kind-1.0.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: string-pot-kind\n"
                                   "Version: 1.0\n")
    (info / "entry_points.txt").write_text(
        "[zerocal.sim_sensors]\nstring_pot = sim_sensor:SimulatedStringPot\n")
    script = ("from controller_stub.sensors.registry import sensor_factories, "
              "SensorPluginError\n"
              "print(sorted(sensor_factories()))\n"
              f"try:\n    sensor_factories([{KIND!r}])\n"
              "except SensorPluginError as exc:\n    print(exc)\n")
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          timeout=60, cwd=Path(__file__).resolve().parents[2],
                          env={**os.environ, "PYTHONPATH": os.pathsep.join([str(tmp_path),
                                                                           KIND])})
    assert done.returncode == 0, done.stderr
    listed, refused = done.stdout.splitlines()
    assert listed == "['string_pot']"
    assert "simulated sensor 'string_pot' is already registered" in refused


@pytest.fixture
async def stub() -> AsyncIterator[ControllerServer]:
    """The stub with the folder's simulated sensor, on 127.0.0.1 port 0 in this loop."""
    scenario = scenario_from_dict({"seed": 5, "server": {"token": TOKEN},
                                   "sensors": {"string_pot": {"sigma": 1e-6}}})
    server = ControllerServer.from_scenario(scenario, sensor_folders=[KIND])
    await server.start("127.0.0.1", 0)
    yield server
    await server.close()


async def test_sensor_read_answers_with_the_true_cable_length(stub: ControllerServer) -> None:
    host, port = stub.address
    async with ControllerClient.connect(host, port, token=TOKEN, timeout=5.0) as client:
        described = await client.sensor_read("string_pot", {"what": "describe"})
        reading = await client.sensor_read("string_pot", {"what": "length", "average": 4})
    assert described.reading["sigma"] == 1e-6 and described.reading["max_length"] == 2.0
    assert np.allclose(reading.q, stub.sim.joint_positions())
    capture = stub.sim.scenario.motion.capture_s  # each reading, stamped at its start
    assert reading.time == pytest.approx(described.time + capture, abs=1e-9)
    assert stub.sim.time == pytest.approx(reading.time + capture, abs=1e-9)
    truth = stub.sensors.truth()["string_pot"]
    T = stub.sim.flange_pose()
    true_length = np.linalg.norm(T[:3, :3] @ truth["tool"] + T[:3, 3] - truth["anchor"])
    assert reading.reading["sigma"] == pytest.approx(0.5e-6)
    assert abs(reading.reading["length"] - true_length) < 5 * 0.5e-6


@pytest.mark.parametrize(("sensor", "request_", "code", "words"), [
    ("laser_line", {"what": "length"}, "refused", "no simulated sensor 'laser_line'"),
    ("string_pot", {"what": "colour"}, "bad_message", "'what' is 'colour'"),
    ("string_pot", {"what": "length", "average": "4"}, "bad_message", "'average'"),
    ("string_pot", {"what": "length", "average": 1000}, "bad_message", "'average'"),
])
async def test_a_request_the_controller_cannot_read_is_a_clear_error(
        stub: ControllerServer, sensor: str, request_: dict[str, object], code: str,
        words: str) -> None:
    host, port = stub.address
    async with ControllerClient.connect(host, port, token=TOKEN, timeout=5.0) as client:
        with pytest.raises(ControllerError) as refused:  # refused: ControllerRefusedError;
            await client.sensor_read(sensor, request_)  # bad_message: ProtocolViolation
        assert f"(code {code}" in str(refused.value) and words in str(refused.value)
        assert (await client.sensor_read("string_pot", {"what": "describe"})).reading  # serving on


@pytest.mark.filterwarnings("ignore:Pydantic serializer warnings")  # built unvalidated
@pytest.mark.parametrize(("fields", "words"), [
    ({"sensor": "String Pot", "request": {}}, "sensor"),
    ({"sensor": "string_pot", "request": [1, 2]}, "request"),
    ({"sensor": "string_pot", "request": {"x": list(range(MAX_SENSOR_NODES))}}, "values"),
    ({"sensor": "string_pot", "request": {"x": "y" * 1001}}, "string longer"),
    ({"request": {}}, "sensor"),
])
async def test_a_broken_sensor_read_is_a_bad_message(stub: ControllerServer,
                                                     fields: dict[str, object],
                                                     words: str) -> None:
    """Headers no valid client sends (built unvalidated, sent as bytes): the session
    answers each with `bad_message` naming the field, and keeps serving."""
    client = await RawClient.open(stub)
    try:
        broken = SensorRead.model_construct(id=client.conn.next_id(), kind="sensor_read",
                                              **fields)
        reply = await client.request(broken)
        assert reply.kind == "error" and reply.code == "bad_message", reply
        assert words in reply.message and reply.reply_to == broken.id
        reply = await client.request(m.Heartbeat(id=client.conn.next_id()))
        assert reply.kind == "heartbeat_reply"
    finally:
        await client.close()


async def test_sensor_read_needs_an_authenticated_session(stub: ControllerServer) -> None:
    host, port = stub.address
    async with ControllerClient.connect(host, port, token=None, timeout=5.0) as client:
        with pytest.raises(ControllerRefusedError) as refused:
            await client.sensor_read("string_pot", {"what": "describe"})
    assert refused.value.code == "auth_required"
