"""Transport benchmark: request round trip and stereo capture over loopback.

    python bench/bench_transport.py [--requests 2000] [--captures 30] [--in-process]

Starts `controller-stub serve --port 0` (default scenario: 1280x1024 stereo camera) as a
subprocess (or, with --in-process, in this event loop), connects `ControllerClient` over
127.0.0.1 and measures:

- heartbeat and get_state round trips (p50, p99 over `requests` sequential requests);
- end-to-end capture of a stereo pair (median over `captures`), and the renderer's share
  (`Simulation.capture_stereo` timed alone in this process). The robot starts at a pose whose
  camera sees the target (`IN_VIEW_Q`, found with hostpc's IK for the default scenario), so
  the renderer draws the target disk and plate, not only the background.

Targets: heartbeat p50 <= 0.5 ms; stereo pair <= 30 ms (renderer budget <= 15 ms).
"""

from __future__ import annotations

import argparse
import asyncio
import json
import re
import statistics
import subprocess
import sys
import time
from typing import Any

import numpy as np

from hostpc.transport import ControllerClient

# UR5e pose looking down at the default scenario's target from 0.45 m (hostpc IK, look_at)
IN_VIEW_Q = [0.5094, -2.912, 0.7385, 0.5531, -1.5731, 0.8099]


def _scenario():  # type: ignore[no-untyped-def]
    from controller_stub.scenario.spec import default_scenario

    scenario = default_scenario()
    return scenario.model_copy(
        update={"motion": scenario.motion.model_copy(update={"initial_q": IN_VIEW_Q})})

TOKEN = "zerocal-sim"


def _percentiles(samples_s: list[float]) -> dict[str, float]:
    values_ms = np.asarray(samples_s) * 1e3
    return {
        "p50_ms": float(np.percentile(values_ms, 50)),
        "p99_ms": float(np.percentile(values_ms, 99)),
        "mean_ms": float(values_ms.mean()),
        "n": int(values_ms.size),
    }


async def _measure(host: str, port: int, requests: int, captures: int) -> dict[str, Any]:
    async with ControllerClient.connect(host, port, token=TOKEN, timeout=10.0) as client:
        for _ in range(200):  # warm up
            await client.heartbeat()
        heartbeat: list[float] = []
        for _ in range(requests):
            start = time.perf_counter()
            await client.heartbeat()
            heartbeat.append(time.perf_counter() - start)
        state: list[float] = []
        for _ in range(requests):
            start = time.perf_counter()
            await client.state()
            state.append(time.perf_counter() - start)
        await client.capture()  # warm up
        capture: list[float] = []
        shape: tuple[int, ...] = ()
        for _ in range(captures):
            start = time.perf_counter()
            left, right, _, _ = await client.capture("target")
            capture.append(time.perf_counter() - start)
            shape = left.shape
            assert left.dtype == np.uint8 and right.shape == left.shape
    return {
        "heartbeat": _percentiles(heartbeat),
        "state": _percentiles(state),
        "capture": {
            "median_ms": statistics.median(capture) * 1e3,
            "p99_ms": float(np.percentile(np.asarray(capture) * 1e3, 99)),
            "n": captures,
            "image_shape": list(shape),
            "bytes_per_pair": int(2 * np.prod(shape)),
        },
    }


def _render_share(captures: int) -> dict[str, float]:
    from controller_stub.world.simulation import Simulation

    sim = Simulation(_scenario())
    sim.capture_stereo("target")
    times = []
    for _ in range(captures):
        start = time.perf_counter()
        sim.capture_stereo("target")
        times.append(time.perf_counter() - start)
    return {"median_ms": statistics.median(times) * 1e3}


async def _run_in_process(requests: int, captures: int) -> dict[str, Any]:
    from controller_stub.network.server import ControllerServer

    server = ControllerServer.from_scenario(_scenario())
    host, port = await server.start("127.0.0.1", 0)
    try:
        return await _measure(host, port, requests, captures)
    finally:
        await server.close()


def _run_subprocess(requests: int, captures: int) -> dict[str, Any]:
    import tempfile

    scenario_file = tempfile.NamedTemporaryFile("w", suffix=".json", delete=False)
    with scenario_file:
        json.dump({"motion": {"initial_q": IN_VIEW_Q}}, scenario_file)
    command = [sys.executable, "-m", "controller_stub", "serve", "--port", "0",
               "--scenario", scenario_file.name]
    process = subprocess.Popen(command, stdout=subprocess.PIPE, text=True)
    try:
        assert process.stdout is not None
        line = process.stdout.readline().strip()
        match = re.match(r"^listening on ([0-9.]+):(\d+)$", line)
        if not match:
            raise RuntimeError(f"controller-stub did not start: {line!r}")
        return asyncio.run(_measure(match[1], int(match[2]), requests, captures))
    finally:
        process.terminate()
        process.wait(timeout=10)
        import os

        os.unlink(scenario_file.name)


def run(requests: int = 2000, captures: int = 30, in_process: bool = False) -> dict[str, Any]:
    """Run the benchmark; returns the figures (milliseconds) and whether targets are met."""
    if in_process:
        figures = asyncio.run(_run_in_process(requests, captures))
    else:
        figures = _run_subprocess(requests, captures)
    figures["render"] = _render_share(min(captures, 20))
    figures["server"] = "in-process" if in_process else "subprocess"
    figures["targets"] = {
        "heartbeat_p50_le_0.5ms": figures["heartbeat"]["p50_ms"] <= 0.5,
        "stereo_pair_le_30ms": figures["capture"]["median_ms"] <= 30.0,
        "render_le_15ms": figures["render"]["median_ms"] <= 15.0,
    }
    return figures


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--requests", type=int, default=2000)
    parser.add_argument("--captures", type=int, default=30)
    parser.add_argument("--in-process", action="store_true", help="server in this event loop")
    args = parser.parse_args(argv)
    print(json.dumps(run(args.requests, args.captures, args.in_process), indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
