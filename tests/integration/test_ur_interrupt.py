"""Ctrl-C during a UR move stops the arm: `hostpc calibrate --driver ur` (a real subprocess,
the real ur_rtde library) against `controller-stub serve --ur` at time_scale 1 gets SIGINT
(or SIGTERM) while the arm moves (seen over RTDE by this test's own receive interface); the driver's
asynchronous moveJ is stopped with stopJ (2 rad/s^2), so the arm comes to rest a ramp's
length after the signal, short of the target, and the interrupt line says so. With the old
blocking moveJ the arm ran on to the target and the process did not end within 30 s."""

from __future__ import annotations

import re
import signal
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest

rtde_receive = pytest.importorskip("rtde_receive")

from hostpc.robots.simulator import default_sim_scenario  # noqa: E402
from hostpc.robots.ur_link import INTERRUPT_DECELERATION, MAX_JOINT_SPEED  # noqa: E402
from tests.integration.test_calibrate_sim import sim_scenario, truth_rig_file  # noqa: E402
from tests.integration.test_interrupt_motion import ENV, REPO  # noqa: E402
from tests.integration.ur_stub import calibrate_command, ur_stub_process  # noqa: E402

SPEED = 0.05
"""Speed fraction of the run: 0.157 rad/s, so a move lasts seconds."""
REACTION_S = 0.3
"""Generous bound on the time from SIGINT to the stopJ arriving (Python's signal handling,
the event loop, ur_rtde's command round trip)."""


def _moving(receive: object) -> tuple[np.ndarray, float]:
    """(q (6,), the fastest joint's speed) of one RTDE sample."""
    q = np.array(receive.getActualQ())  # type: ignore[attr-defined]
    qd = np.array(receive.getActualQd())  # type: ignore[attr-defined]
    return q, float(np.max(np.abs(qd)))


@pytest.mark.parametrize(("signum", "code"), [(signal.SIGINT, 130), (signal.SIGTERM, 143)],
                         ids=["ctrl-c", "sigterm"])
def test_ctrl_c_during_a_ur_move_stops_the_arm(tmp_path: Path, signum: int, code: int
                                               ) -> None:
    """SIGTERM (a station's stop, `kill`) likewise: it cancels the run as Ctrl-C does."""
    rig = truth_rig_file(sim_scenario(), tmp_path / "rig.json")
    out = tmp_path / "run"
    with ur_stub_process(tmp_path / "stub", base=default_sim_scenario(1.0)) as stub:
        receive = rtde_receive.RTDEReceiveInterface("127.0.0.1")
        try:
            command = calibrate_command(stub, rig, out, SPEED)
            process = subprocess.Popen(command, cwd=REPO, env=ENV, stdout=subprocess.PIPE,
                                       stderr=subprocess.PIPE, text=True)
            try:
                deadline = time.monotonic() + 60
                speed = 0.0
                while time.monotonic() < deadline and process.poll() is None and speed <= 0.0:
                    time.sleep(0.01)
                    _, speed = _moving(receive)
                time.sleep(0.3)  # into the move (cruise at 0.157 rad/s after 0.11 s)
                q_signal, speed = _moving(receive)
                while time.monotonic() < deadline and process.poll() is None and speed < 0.1:
                    time.sleep(0.01)  # a short move ended: catch the next one cruising
                    q_signal, speed = _moving(receive)
                assert speed >= 0.1, "the arm is not moving"
                process.send_signal(signum)
                _, stderr = process.communicate(timeout=30)
            finally:
                if process.poll() is None:
                    process.kill()
                    process.wait()
            assert process.returncode == code, stderr
            q_end, speed_end = _moving(receive)
            time.sleep(0.5)
            q_later, _ = _moving(receive)
        finally:
            receive.disconnect()
    # at rest, and no further from where the signal came than a reaction and a ramp
    assert speed_end == 0.0
    np.testing.assert_array_equal(q_later, q_end)
    v = SPEED * MAX_JOINT_SPEED
    travel = float(np.max(np.abs(q_end - q_signal)))
    assert travel <= v * REACTION_S + v * v / (2 * INTERRUPT_DECELERATION), travel
    last = stderr.strip().splitlines()[-1]
    match = re.fullmatch(
        r"hostpc calibrate: interrupted \(move_joints interrupted: stopJ sent: motion stopped "
        rf"([0-9.]+) deg short of the target\): continue with hostpc calibrate --resume {out}",
        last)
    assert match is not None, stderr
    assert float(match.group(1)) > 1.0  # seconds of the move were left
