"""One calibration run through the shared runner against a running controller stub
(the Python API the CLI drives: connect, `Runner.run`, close), for the runner tests."""

from __future__ import annotations

from pathlib import Path

from controller_stub.network.server import ControllerServer
from hostpc.calibrate.run_values import RobotInfo, RunOutcome
from hostpc.calibrate.runner import Runner
from hostpc.methods.base import RunSettings
from hostpc.robots.zerocal import ZerocalAdapter
from tests.integration.conftest import TOKEN


async def run_on(server: ControllerServer, run_dir: Path,
                 settings: RunSettings | None = None) -> RunOutcome:
    """The outcome of a run in `run_dir` on `server` (settings None: resume the run the
    folder holds), without a report."""
    host, port = server.address
    robot = await ZerocalAdapter.connect(host, port, token=TOKEN)
    try:
        return await Runner(robot, run_dir, robot_info=RobotInfo(f"{host}:{port}"),
                            settings=settings, report=False).run()
    finally:
        await robot.close()
