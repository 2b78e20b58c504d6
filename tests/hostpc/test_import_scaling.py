"""`hostpc import` stays linear in the rows: the frame guess compares O(n) pose pairs (it
used to build all n^2/2 of them: 1.2 GB at 4,600 rows, killed at 46,000) and reads a bounded
subset of the samples, and a 50,000-row import keeps its traced memory small. Structural
checks (counts and traced bytes), not timings: bench/bench_import.py measures the time."""

from __future__ import annotations

import json
import tracemalloc
from pathlib import Path

import numpy as np
import pytest

from hostpc.cli.main import main
from hostpc.importing.frame_guess import (
    GUESS_MAX_SAMPLES,
    guess_sample_indices,
    hand_eye_pairs,
)
from hostpc.kinematics import forward, get_robot, pose_to_transform
from hostpc.kinematics.rotations import matrix_to_rpy

WORLD = ([1.8, -0.6, 0.3], [0.05, -0.1, 2.6])
TOOL = ([0.02, -0.01, 0.11], [0.3, -0.2, 0.9])


@pytest.mark.parametrize("n_poses", [3, 28, 29, 1_000, 20_000, 1_000_000])
def test_the_hand_eye_step_compares_at_most_two_pairs_per_pose(n_poses):
    first, second = hand_eye_pairs(n_poses)
    assert len(first) == len(second) <= max(400, 2 * n_poses)
    assert np.all(first != second) and first.max() < n_poses and second.max() < n_poses
    if n_poses * (n_poses - 1) // 2 <= 400:  # few poses: every pair, as before
        assert len(first) == n_poses * (n_poses - 1) // 2


def test_the_guess_reads_a_bounded_share_of_every_marker():
    assert len(guess_sample_indices(5_000)) == 5_000
    picked = guess_sample_indices(1_000_000)
    assert len(picked) <= GUESS_MAX_SAMPLES and picked[-1] > 990_000  # spread over the file
    marker = np.zeros(1_000_000, dtype=np.int64)
    marker[123_456:123_466] = 1  # a marker seen in 10 rows only
    picked = guess_sample_indices(len(marker), marker)
    assert len(picked) <= GUESS_MAX_SAMPLES + 10
    assert np.count_nonzero(marker[picked] == 1) == 10
    assert np.all(np.diff(picked) > 0)


def _world_pose_csv(path: Path, n_rows: int) -> None:
    rng = np.random.default_rng(11)
    q = rng.uniform(-2.5, 2.5, size=(n_rows, 6))
    T = (pose_to_transform(*WORLD) @ forward(get_robot("ur10e"), q).T_base_flange
         @ pose_to_transform(*TOOL))
    p = T[:, :3, 3] + rng.normal(0.0, 2e-5, size=(n_rows, 3))
    table = np.column_stack([q, p, matrix_to_rpy(T[:, :3, :3])])
    with path.open("w") as out:
        out.write("q1,q2,q3,q4,q5,q6,x,y,z,roll,pitch,yaw\n")
        np.savetxt(out, table, delimiter=",", fmt="%.10f")


def test_a_50k_row_import_keeps_its_traced_memory_small(tmp_path, capsys):
    rows = 50_000
    csv_path, out = tmp_path / "poses.csv", tmp_path / "poses.json"
    _world_pose_csv(csv_path, rows)
    tracemalloc.start()
    try:
        code = main(["import", str(csv_path), "--method", "world_pose", "--robot", "ur10e",
                     "--columns", "q=q1:q6,x=x,y=y,z=z,roll=roll,pitch=pitch,yaw=yaw",
                     "-o", str(out)])
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert code == 0, capsys.readouterr().err
    # about 60 MB here: the imports, the columns (12 float64 a row) and the guess on 20,000
    # poses; the old importer's pose-pair list alone was 1.25e9 tuples (over 100 GB)
    assert peak < 100e6, f"peak traced memory {peak / 1e6:.0f} MB"
    document = json.loads(out.read_text())
    assert len(document["samples"]) == rows
    # the guess from a strided 20,000 of the poses still finds the frames
    np.testing.assert_allclose(document["frames"]["world"]["xyz"], WORLD[0], atol=1e-4)
    np.testing.assert_allclose(document["frames"]["tool"]["xyz"], TOOL[0], atol=1e-4)
