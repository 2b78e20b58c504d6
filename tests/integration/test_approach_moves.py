"""Free moves through via-points (hostpc.methods.approach_moves) against the controller
stub on 127.0.0.1: with backlash in the model a tour in which joint 1 always turns the same
way is brought in from both sides, and every recorded approach sign is the direction the
simulated controller's backlash state says the joint last moved."""

from __future__ import annotations

import numpy as np

from hostpc.kinematics import get_robot
from hostpc.methods.approach_moves import ApproachMoves
from hostpc.methods.base import RunSettings, SampleRecord
from hostpc.robots.zerocal import ZerocalAdapter
from tests.integration.conftest import TOKEN, StartStub

HOME = np.array([0.0, -1.9, 1.9, -1.6, -1.5708, 0.0])


def one_way_tour(n_poses: int = 24) -> np.ndarray:
    """Poses (N, 6): joint 1 always turns in +, joints 2-6 go back and forth."""
    q = np.tile(HOME, (n_poses, 1))
    q[:, 0] += np.linspace(0.0, 0.6, n_poses)
    q[:, 1:] += 0.05 * np.tile([[1.0], [-1.0]], (n_poses // 2, 5))
    return q


async def tour(start_stub: StartStub, effects: str | None) -> tuple[np.ndarray, int, float]:
    """(recorded approach signs (N, 6), via-points, simulated seconds) of the tour."""
    server = await start_stub({"motion": {"initial_q": HOME.tolist()}})
    host, port = server.address
    moves = ApproachMoves(RunSettings(method="stereo_target", effects=effects),
                          get_robot("ur5e"))
    robot = await ZerocalAdapter.connect(host, port, token=TOKEN)
    signs = []
    try:
        q_from: np.ndarray | None = np.asarray((await robot.state()).q, float)
        started = float(server.sim.truth()["time_s"])
        for index, q in enumerate(one_way_tour()):
            outcome = await moves.move(robot, "fit", index, q, q_from)
            assert not isinstance(outcome, SampleRecord), outcome
            recorded = moves.signs(q_from, outcome.q)
            # the controller's own backlash state: the direction each joint last moved
            np.testing.assert_array_equal(recorded, server.sim.truth()["approach"])
            signs.append(recorded)
            q_from = np.asarray(outcome.q, float)
        elapsed = float(server.sim.truth()["time_s"]) - started
    finally:
        await robot.close()
    return np.array(signs), moves.vias, elapsed


async def test_a_one_way_joint_is_brought_in_from_both_sides(start_stub: StartStub) -> None:
    plain, vias, plain_time = await tour(start_stub, None)
    assert vias == 0 and np.all(plain[1:, 0] > 0)  # joint 1: always in +
    balanced, vias, balanced_time = await tour(start_stub, "+backlash")
    share = np.mean(balanced > 0, axis=0)
    assert 0.3 < share[0] < 0.7 and vias > 0
    np.testing.assert_array_equal(balanced[:, 1:], plain[:, 1:])  # the others as before
    print(f"{vias} via-points; simulated robot time {plain_time:.1f} s plain, "
          f"{balanced_time:.1f} s balanced")
