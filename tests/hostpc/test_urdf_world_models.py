"""world_point and world_pose on the 7-axis URDF arm with a prismatic lift: data made by an
independent forward model (the plain product of URDF transforms is checked against the
chain in test_urdf_prismatic.py), noise-free recovery, identifiability named, and a
Monte-Carlo check of the fitted sigmas.

Needs the world_point / world_pose measurement models (skipped until they are registered).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from hostpc.kinematics import forward, pose_to_transform
from hostpc.kinematics.rotations import matrix_to_rpy, rotvec_to_matrix
from hostpc.kinematics.urdf import load_urdf_chain

URDF = Path(__file__).resolve().parents[1] / "data" / "arm7_prismatic.urdf"
ROBOT = {"urdf": str(URDF), "base_link": "base_link", "tip_link": "tool0"}
OFFSETS = np.array([0.0021, np.radians(0.3), np.radians(-0.2), np.radians(0.25),
                    np.radians(-0.4), np.radians(0.15), np.radians(0.35)])  # lift in m
W_NOM = pose_to_transform([1.8, -0.6, 0.2], [0.02, -0.01, 2.4])
W_TRUE = W_NOM @ pose_to_transform([0.002, -0.001, 0.0015], [0.001, 0.002, -0.0015])
X_NOM = pose_to_transform([0.02, 0.0, 0.05], [0.0, 0.0, 0.3])
X_TRUE = X_NOM @ pose_to_transform([0.0005, -0.0008, 0.001], [0.002, -0.001, 0.003])
MARKERS = {"a": np.array([0.03, -0.02, 0.06]), "b": np.array([-0.04, 0.03, 0.05])}
MARKER_ERROR = np.array([0.0004, -0.0003, 0.0006])


def _registered(name: str) -> bool:
    from hostpc.dataset.kind_registry import measurement_kinds

    return name in measurement_kinds()


def _poses(n: int = 60, seed: int = 2) -> np.ndarray:
    chain = load_urdf_chain(URDF, "base_link", "tool0")
    rng = np.random.default_rng(seed)
    return rng.uniform(np.maximum(chain.q_min, -2.5), np.minimum(chain.q_max, 2.5),
                       size=(n, chain.n))


def _true_flange(q: np.ndarray) -> np.ndarray:
    return forward(load_urdf_chain(URDF, "base_link", "tool0"), q + OFFSETS).T_base_flange


def _pose(T: np.ndarray) -> dict[str, list[float]]:
    return {"xyz": T[:3, 3].tolist(), "rpy": matrix_to_rpy(T[:3, :3]).tolist()}


def world_pose_document(q, rng=None, sigma=1e-4, sigma_angle=1e-3, known=()):
    T = W_TRUE @ _true_flange(q) @ X_TRUE
    samples = []
    for k, Tk in enumerate(T):
        p, R = Tk[:3, 3].copy(), Tk[:3, :3]
        if rng is not None:
            p = p + rng.normal(scale=sigma, size=3)
            R = rotvec_to_matrix(rng.normal(scale=sigma_angle, size=3)) @ R
        samples.append({"q": q[k].tolist(), "p": p.tolist(),
                        "rpy": matrix_to_rpy(R).tolist(), "sigma": sigma,
                        "sigma_angle": sigma_angle})
    return {"format": "zerocal-dataset/1", "method": "world_pose", "robot": ROBOT,
            "frames": {"world": _pose(W_NOM), "tool": _pose(X_NOM)}, "known": list(known),
            "samples": samples}


def world_point_document(q):
    T = W_TRUE @ _true_flange(q)
    samples = []
    for k, Tk in enumerate(T):
        name = "ab"[k % 2]
        m = MARKERS[name] + MARKER_ERROR
        samples.append({"q": q[k].tolist(), "marker": name,
                        "p": (Tk[:3, :3] @ m + Tk[:3, 3]).tolist(), "sigma": 1e-5})
    return {"format": "zerocal-dataset/1", "method": "world_point", "robot": ROBOT,
            "frames": {"world": _pose(W_NOM),
                       "markers": {k: v.tolist() for k, v in MARKERS.items()}},
            "known": [], "samples": samples}


@pytest.mark.skipif(not _registered("world_pose"), reason="needs the world_pose model")
def test_world_pose_noise_free_on_the_urdf_arm():
    from hostpc.dataset import dataset_from_dict
    from hostpc.fitting import fit

    result = fit(dataset_from_dict(world_pose_document(_poses())), cv_folds=0)
    assert result.converged and result.rms < 1e-10
    held = {d.fixed for d in result.unidentifiable}
    # the lift and joint 1 share one axis line at the base: the free world frame takes
    # both; the last joint's zero goes with the free tool frame
    assert {"joint_offsets.q1", "joint_offsets.q2", "joint_offsets.q7"} <= held
    for j in (3, 4, 5, 6):
        assert abs(result.value(f"joint_offsets.q{j}") - OFFSETS[j - 1]) < 1e-9, j
    # a known world frame defines the lift's and joint 1's zeros too
    document = _with_true_world(world_pose_document(_poses(), known=("world",)))
    result = fit(dataset_from_dict(document), cv_folds=0)
    held = {d.fixed for d in result.unidentifiable}
    assert held == {"joint_offsets.q7"}
    for j in range(1, 7):
        assert abs(result.value(f"joint_offsets.q{j}") - OFFSETS[j - 1]) < 1e-9, j


def _with_true_world(document):
    return {**document, "frames": {**document["frames"], "world": _pose(W_TRUE)}}


@pytest.mark.skipif(not _registered("world_point"), reason="needs the world_point model")
def test_world_point_noise_free_on_the_urdf_arm():
    from hostpc.dataset import dataset_from_dict
    from hostpc.fitting import fit

    result = fit(dataset_from_dict(world_point_document(_poses(80))), cv_folds=0)
    assert result.converged and result.rms < 1e-10
    held = {d.fixed for d in result.unidentifiable}
    assert {"joint_offsets.q1", "joint_offsets.q2", "joint_offsets.q7"} <= held
    for j in (3, 4, 5, 6):
        assert abs(result.value(f"joint_offsets.q{j}") - OFFSETS[j - 1]) < 1e-9, j


@pytest.mark.skipif(not _registered("world_pose"), reason="needs the world_pose model")
def test_world_pose_sigma_matches_the_monte_carlo_spread_on_the_urdf_arm():
    from hostpc.dataset import dataset_from_dict
    from hostpc.fitting import fit

    q = _poses(40, seed=5)
    rng = np.random.default_rng(9)
    estimates, sigmas = [], None
    for _ in range(100):
        document = _with_true_world(world_pose_document(q, rng=rng, known=("world",)))
        result = fit(dataset_from_dict(document), cv_folds=0)
        names = [f"joint_offsets.q{j}" for j in range(1, 7)]
        estimates.append([result.value(n) for n in names])
        sigmas = np.array([result.sigma(n) for n in names])
    spread = np.std(np.array(estimates), axis=0, ddof=1)
    assert sigmas is not None
    np.testing.assert_allclose(spread / sigmas, 1.0, atol=0.2)
