"""The UR personality's program state after a dashboard `stop`: a UR reports its program
stopped once the stop is taken, while the program (its motion's stop ramp) still winds down.
A host that asked why its move ended read "running" in that gap and took the stop for a
missed probe contact (test_ur_adapter's controller-stopped approach, in a full suite)."""

from __future__ import annotations

import asyncio

from controller_stub.scenario.spec import scenario_from_dict
from controller_stub.ur.personality import UrPersonality
from controller_stub.world.simulation import Simulation


async def test_a_stopped_program_reads_stopped_while_it_winds_down() -> None:
    robot = UrPersonality(Simulation(scenario_from_dict({"robot": "ur5e"})))

    async def program() -> None:  # a program whose stop takes a while (a stop ramp)
        try:
            await asyncio.sleep(30.0)
        finally:
            await asyncio.sleep(0.2)

    robot._program = asyncio.create_task(program())  # as run_program starts one
    await asyncio.sleep(0.01)
    assert robot.program_running()
    robot.stop_program()
    await asyncio.sleep(0.05)  # the program still winds down
    assert not robot._program.done()
    assert not robot.program_running()
    await asyncio.sleep(0.3)
    assert robot._program.done() and not robot.program_running()
