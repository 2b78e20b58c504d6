"""Real data: FIGAROH's UR10e experiment (tests/data/README.md) through `hostpc import`, the
world_pose model, the fit and the diagnosis.

Needs the world_pose measurement model (hostpc/model/measurements/, issue 13 item 1); the
import half runs everywhere, the fit half is skipped until the model is registered.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from hostpc.cli.main import main

DATA = Path(__file__).resolve().parents[1] / "data"
FIGAROH = DATA / "figaroh_ur10e_calibration.csv"
COLUMNS = "q=shoulder_pan_joint:wrist_3_joint,x=x1,y=y1,z=z1,roll=phix1,pitch=phiy1,yaw=phiz1"


def _world_pose_registered() -> bool:
    from hostpc.dataset.kind_registry import measurement_kinds

    return "world_pose" in measurement_kinds()


@pytest.fixture(scope="module")
def figaroh_dataset(tmp_path_factory):
    out = tmp_path_factory.mktemp("figaroh") / "ur10e.json"
    assert main(["import", str(FIGAROH), "--method", "world_pose", "--robot", "ur10e",
                 "--sigma", "0.001", "--sigma-angle", "0.0035",  # m, rad: 1 mm, 0.2 deg
                 "--columns", COLUMNS, "-o", str(out)]) == 0
    return out


needs_world_pose = pytest.mark.skipif(not _world_pose_registered(),
                                      reason="needs the world_pose measurement model")


@needs_world_pose
def test_figaroh_ur10e_fit_beats_the_nominal_model_held_out(figaroh_dataset):
    from hostpc.dataset.reading import load_dataset
    from hostpc.fitting import fit

    dataset = load_dataset(figaroh_dataset)
    assert len(dataset.samples.q) == 23
    nominal = fit(dataset, ["world", "tool"], cv_folds=5)
    offsets = fit(dataset, cv_folds=5)  # joint_offsets + the unknown frames
    geometry = fit(dataset, "+geometry", cv_folds=5)
    for result in (nominal, offsets, geometry):
        assert result.converged
    # joints 1 and 6 are not defined against a free world frame and a free tool frame
    held = {d.fixed for d in offsets.unidentifiable}
    assert {"joint_offsets.q1", "joint_offsets.q6"} <= held
    # the real robot's zero offsets are small (within 2 sigma: offsets alone do not beat
    # the nominal model held out); its geometry is not: with it the held-out error, in the
    # measurement's own units (whitened: position and orientation each by its sigma), drops
    # a little (measured with the pose-grouped seeded folds of hostpc/fitting/folds.py: 2.061
    # -> 2.009; with the former interleaved folds 2.13 -> 2.01), the held-out orientation
    # error by a quarter (0.581 -> 0.441 deg); the held-out position error does not (4.14
    # -> 4.40 mm; docs/metrology.md)
    nominal_whitened, nominal_angle = _held_out(nominal)
    geometry_whitened, geometry_angle = _held_out(geometry)
    assert geometry_whitened < 0.99 * nominal_whitened
    assert geometry_angle < 0.8 * nominal_angle
    assert geometry.chi2_dof < nominal.chi2_dof


def _held_out(result) -> tuple[float, float]:
    """5-fold held-out RMS of the whitened residual per row, and of the orientation error
    (rad), each fold refit from the full solution as `fit` does for cv_rms."""
    import numpy as np

    from hostpc.fitting.folds import fold_indices
    from hostpc.fitting.solver import evaluate, levenberg_marquardt

    problem, free = result.problem, ~result.fixed
    n = problem.measured.shape[0]
    whitened, angle = np.empty(n), np.empty(n)
    folds = fold_indices(problem.dataset.samples, 5)
    assert folds is not None
    for test in folds:
        train = np.setdiff1d(np.arange(n), test)
        outcome = levenberg_marquardt(problem.subset(train), result.x, free, loss="linear",
                                      loss_scale=3.0, max_iterations=30)
        held = evaluate(problem.subset(test), outcome.x, jacobian=False)
        whitened[test] = np.sum(held.whitened.reshape(len(test), -1) ** 2, axis=1) / 6
        angle[test] = np.sum(held.raw[:, 3:] ** 2, axis=1)
    return float(np.sqrt(whitened.mean())), float(np.sqrt(angle.mean()))


@needs_world_pose
def test_figaroh_ur10e_diagnoses(figaroh_dataset, capsys):
    assert main(["diagnose", str(figaroh_dataset)]) == 1  # 1: not adequate
    out = capsys.readouterr().out
    assert "NOT adequate" in out  # joint offsets + frames do not explain the real poses
    candidates = out.split("candidate effects", 1)[1].splitlines()[2]
    assert candidates.split()[:2] == ["*", "geometry"]  # ... the geometry does


@needs_world_pose
def test_figaroh_ur10e_converges_at_every_level(figaroh_dataset):
    """Every built-in level converges with no offset sigma beyond a few degrees; the
    pose-grouped held-out table of `--effects auto` (docs/real-data.md) keeps the nominal
    model: nothing beats it by more than one standard error on 23 poses."""
    from tests.hostpc.realdata import check_every_level

    table = check_every_level(figaroh_dataset, ["world", "tool"])["table"]
    assert table["nominal"]["cv_rms"] == pytest.approx(4.135e-3, rel=0.01)
    assert table["offsets"]["cv_rms"] == pytest.approx(4.116e-3, rel=0.01)
    assert table["offsets + geometry"]["cv_rms"] == pytest.approx(4.402e-3, rel=0.01)
    assert table["auto"]["name"] == "nominal"
