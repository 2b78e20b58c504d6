"""sphere_probe end to end against the real controller stub on 127.0.0.1.

Plan on the nominal model, acquire through the protocol's guarded move (ZerocalAdapter) or
by polling the probe line over Modbus (pymodbus client against the stub's Modbus server),
build the dataset, solve, and compare with the stub's hidden truth.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from controller_stub.network.server import ControllerServer
from hostpc.dataset import load_dataset, save_dataset
from hostpc.fitting import FitResult
from hostpc.kinds.sphere_probe.acquisition import ContactRecord, acquire
from hostpc.kinds.sphere_probe.dataset import build_dataset, frames_from_result, solve
from hostpc.kinds.sphere_probe.planning.contacts import (
    PlannedContact,
    PlannedOrientation,
    ProbePlan,
    plan_sphere_probe,
)
from hostpc.kinds.sphere_probe.planning.setup import PlanConfig, ProbeSetup
from hostpc.kinematics import get_robot, rot_z
from hostpc.robots.zerocal import ZerocalAdapter
from tests.integration.conftest import TOKEN, StartStub


def setup_of(server: ControllerServer, **overrides: Any) -> ProbeSetup:
    """The cell as a user would describe it: the scenario's NOMINAL probe values."""
    probe = server.sim.scenario.probe
    values: dict[str, Any] = dict(
        sphere_centre=probe.sphere_centre, sphere_radius=probe.sphere_radius,
        stylus_radius=probe.stylus_radius, tip=probe.tip, io_line=probe.io_line,
        repeatability=probe.repeatability_sigma)
    values.update(overrides)
    return ProbeSetup(**values)


async def run_probe(server: ControllerServer, setup: ProbeSetup, config: PlanConfig,
                    guarded: Any = None, edit_plan: Any = None) -> list[ContactRecord]:
    host, port = server.address
    robot = await ZerocalAdapter.connect(host, port, token=TOKEN, timeout=10.0)
    try:
        state = await robot.state()
        plan = plan_sphere_probe(get_robot(state.robot), setup, config, state.q,
                                    state.q_min, state.q_max)
        if edit_plan is not None:
            plan = edit_plan(plan)
        stepped = None if guarded is None else guarded(robot)
        return await acquire(robot, plan, setup, config, guarded=stepped)
    finally:
        await robot.close()


def truth_offsets(server: ControllerServer) -> np.ndarray:
    return np.asarray(server.sim.truth()["zero_errors"], float)


def check_offsets(result: FitResult, truth: np.ndarray, expect_fixed: set[str]) -> None:
    """Identifiable offsets within 3 sigma; the unidentifiable ones held, not invented."""
    fixed = {d.fixed for d in result.unidentifiable}
    assert fixed == expect_fixed
    for j, value in enumerate(truth):
        name = f"joint_offsets.q{j + 1}"
        estimate = result.parameters[name]
        if name in expect_fixed:
            assert estimate.fixed and estimate.value == 0.0
            continue
        assert estimate.std is not None and estimate.std < 1e-4
        assert abs(estimate.value - value) < 3 * estimate.std, (name, estimate, value)


@pytest.mark.slow
async def test_calibration_recovers_the_truth(start_stub: StartStub, tmp_path: Path) -> None:
    # a surveyed sphere (no hidden centre error), so the `known` datum can be tested too
    server = await start_stub({"probe": {"sphere_centre_error": [0.0, 0.0, 0.0]}})
    config = PlanConfig()
    setup = setup_of(server)
    records = await run_probe(server, setup, config)
    assert len(records) == 5 * config.n_orientations >= 100
    assert all(r.contact for r in records)
    truth = server.sim.truth()
    offsets = np.asarray(truth["zero_errors"], float)
    sphere_true = np.asarray(truth["probe"]["sphere_centre"], float)
    tip_true = np.asarray(truth["probe"]["stylus_tip"], float)

    # free sphere and tip: joint 1 (about base z, against the sphere centre) and joint 6
    # (about the flange z, against the tip) cannot be seen, and are reported
    dataset = build_dataset(server.sim.robot_name, setup, records)
    path = tmp_path / "probe.json"
    save_dataset(dataset, path)
    result = solve(load_dataset(path))
    assert result.converged
    check_offsets(result, offsets, {"joint_offsets.q1", "joint_offsets.q6"})
    assert any("sphere" in d.description and "joint_offsets.q1" in d.parameters
               for d in result.unidentifiable)
    lo, hi = 0.5, 1.6
    assert lo < result.chi2_dof < hi
    # in the gauge held by the fit (q1 = q6 = 0) the frames are the truth turned by the
    # held offsets: P_b about base z by -q1, P_t about flange z by +q6
    frames = frames_from_result(result)
    assert np.linalg.norm(frames["sphere"] - rot_z(-offsets[0]) @ sphere_true) < 5e-5
    assert np.linalg.norm(frames["tool"] - rot_z(offsets[5]) @ tip_true) < 5e-5

    # the known-sphere datum: joint 1 becomes identifiable, the sphere stays where surveyed
    known = build_dataset(server.sim.robot_name, setup_of(server, known=("sphere",)),
                             records)
    result_known = solve(known)
    check_offsets(result_known, offsets, {"joint_offsets.q6"})
    frames = frames_from_result(result_known)
    assert np.linalg.norm(frames["sphere"] - sphere_true) < 1e-12
    assert np.linalg.norm(frames["tool"] - rot_z(offsets[5]) @ tip_true) < 5e-5


async def test_missed_contacts_are_reported_and_the_run_goes_on(start_stub: StartStub
                                                                ) -> None:
    server = await start_stub({"faults": {"lose_io_edge_indices": [2, 7]}})
    config = PlanConfig(n_orientations=6)
    setup = setup_of(server)

    def shorten(plan: ProbePlan) -> ProbePlan:
        # contact 11 ends its travel 8 mm before the surface: no edge before the end
        first = plan.orientations[2]
        c = first.contacts[1]
        short = PlannedContact(c.group, c.index, c.normal, c.q_start,
                                  c.q_start + 0.1 * (c.q_target - c.q_start), c.speed)
        contacts = (first.contacts[0], short, *first.contacts[2:])
        orientations = list(plan.orientations)
        orientations[2] = PlannedOrientation(first.group, first.rotation,
                                                first.stylus_direction, first.q_hover,
                                                contacts)
        return ProbePlan(tuple(orientations), plan.rejected)

    records = await run_probe(server, setup, config, edit_plan=shorten)
    assert len(records) == 30
    missed = [r for r in records if not r.contact]
    assert [(r.group, r.index) for r in missed] == [(0, 2), (1, 2), (2, 1)]
    assert all(r.reason == "no_contact" and r.q_latched is None for r in missed)
    # a missed move ran to its travel limit
    for r in missed:
        assert r.q_end is not None
    dataset = build_dataset("ur5e", setup, records)
    assert dataset.n_samples == 27
    assert dataset.extra_fields["sphere_probe"]["missed"] == [
        {"group": 0, "index": 2, "reason": "no_contact"},
        {"group": 1, "index": 2, "reason": "no_contact"},
        {"group": 2, "index": 1, "reason": "no_contact"}]
    result = solve(dataset)
    assert result.converged


@pytest.mark.slow
async def test_hidden_trigger_latency_is_found(start_stub: StartStub, tmp_path: Path,
                                              capsys: pytest.CaptureFixture[str]) -> None:
    latency = 0.004
    server = await start_stub({"truth": {"probe_trigger_latency_s": latency}})
    setup = setup_of(server)
    records = await run_probe(server, setup, PlanConfig())
    dataset = build_dataset("ur5e", setup, records)
    path = tmp_path / "probe.json"
    save_dataset(dataset, path)
    loaded = load_dataset(path)
    from hostpc.diagnostics.adequacy import assess

    lean = solve(loaded, estimate=False)
    assert not assess(lean, None, 0.01).adequate
    assert lean.chi2_dof > 100
    full = solve(loaded, "+trigger_latency", estimate=False)
    verdict = assess(full, None, 0.01)
    assert verdict.adequate, verdict.reasons
    estimate = full.parameters["trigger_latency.latency"]
    assert estimate.std is not None
    assert abs(estimate.value - latency) < 3 * estimate.std + 2e-5
    check_offsets(full, truth_offsets(server), {"joint_offsets.q1", "joint_offsets.q6"})

    # the same through the CLI: `hostpc fit FILE --effects +trigger_latency --json`
    from hostpc.cli.main import main

    assert main(["fit", str(path), "--json", "--cv-folds", "0"]) == 0
    lean_doc = json.loads(capsys.readouterr().out)
    assert main(["fit", str(path), "--effects", "+trigger_latency", "--json",
                 "--cv-folds", "0"]) == 0
    full_doc = json.loads(capsys.readouterr().out)
    assert lean_doc["chi2_dof"] > 100 > 2 > full_doc["chi2_dof"]
    assert full_doc["parameters"]["trigger_latency.latency"]["value"] == pytest.approx(
        latency, abs=5e-5)

    # and hostpc.diagnose ranks trigger_latency first (if the diagnose pipeline is there)
    try:
        from hostpc.diagnostics import diagnose
    except ImportError:
        return
    diagnosis = diagnose(str(path))
    assert diagnosis.candidates[0].effect == "trigger_latency"
@pytest.mark.slow
async def test_modbus_polling_path(start_stub: StartStub) -> None:
    from controller_stub.network.modbus_io import ModbusIoServer
    from hostpc.kinds.sphere_probe.probe_modbus import ModbusProbe, SteppedGuardedMove

    server = await start_stub({"probe": {"repeatability_sigma": 0.0}})
    modbus = ModbusIoServer(server.sim, host="127.0.0.1", port=0)
    host, port = await modbus.start()
    probe = await ModbusProbe(host, port, server.sim.scenario.probe.io_line).connect()
    try:
        setup = setup_of(server, repeatability=1e-6)
        config = PlanConfig(n_orientations=20)
        stepped: list[SteppedGuardedMove] = []

        def make(robot: ZerocalAdapter) -> SteppedGuardedMove:
            stepped.append(SteppedGuardedMove(robot, probe))
            return stepped[0]

        records = await run_probe(server, setup, config, guarded=make)
    finally:
        await probe.close()
        await modbus.close()
    assert all(r.contact for r in records) and len(records) == 100
    assert probe.reads >= len(records)
    # the robot was at rest at every reading: no latency, speed 0
    assert all(r.speed == 0.0 for r in records)
    dataset = build_dataset("ur5e", setup, records)
    result = solve(dataset)
    check_offsets(result, truth_offsets(server), {"joint_offsets.q1", "joint_offsets.q6"})
    assert result.chi2_dof < 1.6
    assert math.isfinite(result.rms) and result.rms < 3e-6
