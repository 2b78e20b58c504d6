"""A large problem's Jacobian evaluated in chunks of samples equals the one-piece evaluation,
and a linear basis shared by all samples stays one matrix (memory flat in N)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from hostpc.dataset import load_dataset
from hostpc.fitting import solver
from hostpc.model.problem import build_problem

EXAMPLE = Path(__file__).parents[2] / "examples" / "ur5e_stereo_hidden_compliance.json"


def test_chunks_give_the_one_piece_evaluation(monkeypatch: pytest.MonkeyPatch) -> None:
    problem = build_problem(load_dataset(EXAMPLE), "joint_offsets,tool,target,geometry")
    x = np.random.default_rng(5).standard_normal(problem.layout.size) * 1e-3
    whole = solver.evaluate(problem, x)
    monkeypatch.setattr(solver, "CHUNK_SAMPLES", 7)  # 60 samples: 9 chunks, the last short
    chunked = solver.evaluate(problem, x)
    assert whole.jacobian is not None and chunked.jacobian is not None
    np.testing.assert_allclose(chunked.raw, whole.raw, rtol=0, atol=1e-15)
    np.testing.assert_allclose(chunked.whitened, whole.whitened, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(chunked.jacobian, whole.jacobian, rtol=1e-12, atol=1e-9)


def test_a_shared_geometry_basis_is_one_matrix_in_every_subset() -> None:
    problem = build_problem(load_dataset(EXAMPLE), "joint_offsets,geometry")
    basis = next(b for b in problem.linear_bases if b is not None and b.shape[1] > 6)
    assert basis.strides[0] == 0 and basis.shape[0] == problem.measured.shape[0]
    part = problem.subset(np.array([3, 5, 5, 40]))
    sub = next(b for b in part.linear_bases if b is not None and b.shape[1] > 6)
    assert sub.strides[0] == 0 and sub.shape == (4, *basis.shape[1:])
    np.testing.assert_array_equal(sub[2], basis[5])
    masked = problem.subset(np.arange(problem.measured.shape[0]) % 2 == 0)
    assert next(b for b in masked.linear_bases
                if b is not None and b.shape[1] > 6).shape[0] == problem.measured.shape[0] // 2
