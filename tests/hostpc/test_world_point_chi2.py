"""world_point's chi2/dof at a short plan, measured through the simulated laser tracker.

The push guard refuses a fit whose chi2/dof is above its band (chi-square p < 1e-3,
`hostpc.diagnostics.adequacy`). That is a false REFUSE of a clean robot at a rate of
1e-3 only if the chi2 is counted right: the residuals whitened by the covariance the tracker
states for each reading (`controller_stub/sensors/world_point.py`: distance noise along the
line of sight, angle noise across it) and the dof the measured axes minus the estimated
parameters. Here 8 poses (the shortest plan that identifies all six offsets with world and
markers known: 24 residuals, 6 offsets, 18 dof) are measured many times over by the stub's
own tracker in the clean default world and fitted: the mean chi2/dof is 1 and the share
above the band is about 1e-3. A dof counted as 3N (no parameters) gives a mean of 0.75, a
covariance that omits the tracker's angular term 2 or more.
"""

from __future__ import annotations

import numpy as np

from controller_stub.scenario.spec import scenario_from_dict
from controller_stub.world.simulation import Simulation
from hostpc.dataset import Dataset, FramePose, RobotDescription, Samples
from hostpc.diagnostics.adequacy import chi2_dof_upper
from hostpc.fitting import solve
from hostpc.model.problem import build_problem

POSES = 8
TRIALS = 200


def _visible_poses(sim: Simulation, count: int, rng: np.random.Generator) -> np.ndarray:
    """(count, n) reported joint angles at which the reflector faces the tracker."""
    lo, hi = sim.joint_limits()
    kept: list[np.ndarray] = []
    while len(kept) < count:
        q = rng.uniform(np.maximum(lo, -3.0), np.minimum(hi, 3.0))
        _, lost = sim.tracker.measure(sim.physics.flange_pose(
            sim.body.physical_angles(q)[None], 0.0)[0])
        if not lost:
            kept.append(q)
    return np.array(kept)


def _measured(sim: Simulation, q: np.ndarray) -> Dataset:
    """The tracker's readings at the reported angles q (N, n) as a world_point dataset
    with the tracker's nominal frames, both known."""
    points, covs = [], []
    for pose in q:
        seen, _ = sim.tracker.measure(sim.physics.flange_pose(
            sim.body.physical_angles(pose)[None], 0.0)[0])
        points.append(seen["smr1"]["p"])
        covs.append(seen["smr1"]["cov"])
    described = sim.tracker.description()
    n = q.shape[0]
    samples = Samples(q=q, p=np.array(points), cov=np.array(covs),
                      fields={"marker": np.array(["smr1"] * n), "mask": np.ones((n, 3))})
    world = described["world_base"]
    return Dataset(method="world_point", robot=RobotDescription(name="ur5e"),
                   frames={"world": FramePose(xyz=np.array(world["xyz"]),
                                              rpy=np.array(world["rpy"])),
                           "markers": {k: np.array(v)
                                       for k, v in described["reflectors"].items()}},
                   samples=samples, known=("world", "markers"))


def test_a_clean_world_at_eight_poses_passes_the_chi2_band_at_its_stated_rate() -> None:
    sim = Simulation(scenario_from_dict({"seed": 11}))
    rng = np.random.default_rng(4)
    ratios, refused = [], 0
    for _ in range(TRIALS):
        result = solve(build_problem(_measured(sim, _visible_poses(sim, POSES, rng))),
                       cv_folds=0)
        assert result.converged
        assert result.dof == 3 * POSES - 6
        ratios.append(result.chi2_dof)
        refused += result.chi2_dof > chi2_dof_upper(result.dof)
    # chi2/dof on 18 dof: mean 1, sd 1/3; the mean of 200 has sd 0.024
    assert abs(np.mean(ratios) - 1.0) < 0.075, np.mean(ratios)
    # at p < 1e-3 the expected count is 0.2 of 200; 3 or more has probability 0.001
    assert refused <= 2, refused
