"""sphere_probe host-side timing against the controller stub on 127.0.0.1.

    python bench/bench_sphere_probe.py

Figures (wall time on the host, the stub running in the same process with time_scale 0, so
motions take no time): planning per contact, acquisition per contact through the protocol
(5 requests: hover, start, guarded move, start, hover) and through the Modbus polling
path, the dataset (closed-form initial estimate + contact normals), and the full joint
solve (LM with 5-fold cross-validation) with and without trigger_latency.
"""

from __future__ import annotations

import asyncio
import time
from typing import Any

import numpy as np

from controller_stub.network.modbus_io import ModbusIoServer
from controller_stub.network.server import ControllerServer
from controller_stub.scenario.spec import scenario_from_dict
from hostpc.kinds.sphere_probe.acquisition import acquire
from hostpc.kinds.sphere_probe.dataset import build_dataset, solve
from hostpc.kinds.sphere_probe.planning.contacts import ProbePlan, plan_sphere_probe
from hostpc.kinds.sphere_probe.planning.setup import PlanConfig, ProbeSetup
from hostpc.kinds.sphere_probe.probe_modbus import ModbusProbe, SteppedGuardedMove
from hostpc.kinematics import get_robot
from hostpc.robots.zerocal import ZerocalAdapter

TOKEN = "bench-token"


async def _run(n_orientations: int, modbus_orientations: int) -> dict[str, Any]:
    scenario = scenario_from_dict({"seed": 7, "robot": "ur5e", "server": {"token": TOKEN},
                                   "truth": {"probe_trigger_latency_s": 0.002},
                                   "camera": {"image_width": 320, "image_height": 256}})
    server = ControllerServer.from_scenario(scenario)
    await server.start("127.0.0.1", 0)
    modbus = ModbusIoServer(server.sim, host="127.0.0.1", port=0)
    modbus_host, modbus_port = await modbus.start()
    probe = scenario.probe
    setup = ProbeSetup(sphere_centre=probe.sphere_centre, sphere_radius=probe.sphere_radius,
                          stylus_radius=probe.stylus_radius, tip=probe.tip,
                          io_line=probe.io_line, repeatability=probe.repeatability_sigma)
    config = PlanConfig(n_orientations=n_orientations)
    host, port = server.address
    robot = await ZerocalAdapter.connect(host, port, token=TOKEN)
    try:
        state = await robot.state()
        t = time.perf_counter()
        plan = plan_sphere_probe(get_robot("ur5e"), setup, config, state.q, state.q_min,
                                    state.q_max)
        plan_s = time.perf_counter() - t
        n_contacts = len(plan.contacts)
        t = time.perf_counter()
        records = await acquire(robot, plan, setup, config)
        acquire_s = time.perf_counter() - t
        small = ProbePlan(plan.orientations[:modbus_orientations], 0)
        async with ModbusProbe(modbus_host, modbus_port, probe.io_line) as reader:
            stepped = SteppedGuardedMove(robot, reader)
            t = time.perf_counter()
            modbus_records = await acquire(robot, small, setup, config, guarded=stepped)
            modbus_s = time.perf_counter() - t
    finally:
        await robot.close()
        await modbus.close()
        await server.close()
    t = time.perf_counter()
    dataset = build_dataset("ur5e", setup, records)
    dataset_s = time.perf_counter() - t
    t = time.perf_counter()
    lean = solve(dataset, estimate=False)
    solve_s = time.perf_counter() - t
    t = time.perf_counter()
    full = solve(dataset, "+trigger_latency", estimate=False)
    solve_latency_s = time.perf_counter() - t
    t = time.perf_counter()
    solve(dataset, "+trigger_latency", estimate=False, cv_folds=0)
    solve_nocv_s = time.perf_counter() - t
    return {
        "contacts": n_contacts,
        "plan_ms_per_contact": 1e3 * plan_s / n_contacts,
        "acquire_ms_per_contact": 1e3 * acquire_s / n_contacts,
        "modbus_ms_per_contact": 1e3 * modbus_s / len(modbus_records),
        "modbus_moves_per_contact": stepped.moves / len(modbus_records),
        "modbus_reads_per_contact": reader.reads / len(modbus_records),
        "dataset_ms": 1e3 * dataset_s,
        "solve_ms": 1e3 * solve_s,
        "solve_with_latency_ms": 1e3 * solve_latency_s,
        "solve_with_latency_no_cv_ms": 1e3 * solve_nocv_s,
        "chi2_dof_default": lean.chi2_dof,
        "chi2_dof_with_latency": full.chi2_dof,
        "latency_fitted_s": full.value("trigger_latency.latency"),
    }


def run(n_orientations: int = 24, modbus_orientations: int = 4) -> dict[str, Any]:
    """Timing figures (see the module docstring) as a dict."""
    return asyncio.run(_run(n_orientations, modbus_orientations))


def main() -> int:
    figures = run()
    width = max(len(k) for k in figures)
    for key, value in figures.items():
        text = f"{value:.4g}" if isinstance(value, float) else str(value)
        print(f"{key:<{width}}  {text}")
    return 0 if np.isfinite(figures["chi2_dof_with_latency"]) else 1


if __name__ == "__main__":
    raise SystemExit(main())
