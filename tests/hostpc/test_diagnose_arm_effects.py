"""An effect in one arm of a dual_loop dataset is traced to that arm: compliance of the
left arm only is found on the left arm's joints, and an offset of the left arm's
measurements (its target seen 1.5 mm deeper than it is) is named by the ``chain`` group
with the size of the difference between the arms. (With two arms that is all the data can
say: each arm has its own base frame and both share the camera, so "left off by +b" and
"right off by -b, camera moved" fit alike.)"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

import hostpc
from hostpc.dataset import Dataset
from hostpc.kinds.dual_loop.planning import plan_poses
from hostpc.kinds.dual_loop.synthesize import synthesize_dual_loop
from hostpc.model.measurements.predict import predict

OFFSETS = {"joint_offsets.left.q3": 1e-3, "joint_offsets.right.q4": -1e-3}
DEPTH_BIAS = 1.5e-3  # m, along the camera's optical axis, on the left arm's samples


def _arms(truth: dict[str, float], seed: int, left_depth_bias: float = 0.0) -> Dataset:
    dataset = synthesize_dual_loop({**OFFSETS, **truth},
                                   plan_poses(50, np.random.default_rng(seed)), seed=seed + 1)
    p = np.array(dataset.samples.p, dtype=float)
    p[dataset.samples.chain == "left", 2] += left_depth_bias
    return replace(dataset, samples=replace(dataset.samples, p=p))


def _depth_slope(diagnosis: hostpc.Diagnosis, parameter: str) -> float:
    """Mean derivative of the left arm's predicted depth (camera z, m) by ``parameter``
    at the fit, by central differences of the model's predictions."""
    fit = diagnosis.check.fit
    k = list(fit.problem.layout.names).index(parameter)
    step = np.zeros_like(fit.x)
    step[k] = 1e-6
    ahead, _ = predict(fit.problem, fit.x + step, jacobian=False)
    behind, _ = predict(fit.problem, fit.x - step, jacobian=False)
    left = np.asarray(fit.problem.dataset.samples.chain) == "left"
    return float(np.mean((ahead - behind)[left, 2]) / 2e-6)


@pytest.mark.parametrize("seed", [1])
def test_compliance_of_one_arm_is_found_on_that_arm(seed: int) -> None:
    diagnosis = hostpc.diagnose(_arms({"joint_compliance.left.c2": 2e-4,
                                       "joint_compliance.left.c4": 2e-4}, seed))
    best = diagnosis.candidates[0]
    assert best.effect == "joint_compliance" and best.significant
    assert best.selected and all(n.startswith("joint_compliance.left.") for n in best.selected)
    found = diagnosis.check.significant_interactions
    assert all(i.variable.startswith("left.") for i in found[:5])  # the left arm's torques
    assert not any(i.variable.startswith("right.") for i in found)
    assert "Residuals follow the gravity torque on joint left.2" in " ".join(diagnosis.advice)


@pytest.mark.parametrize("seed", [1, 2])
def test_an_offset_of_one_arm_is_named_by_the_chain_group(seed: int) -> None:
    diagnosis = hostpc.diagnose(_arms({}, seed, DEPTH_BIAS))
    assert not diagnosis.adequate
    top = diagnosis.check.significant_interactions[0]
    assert top.variable == "chain" and top.basis == "per level"
    assert [level for level, _ in top.level_shifts] == ["left", "right"]
    (_, left), (_, right) = top.level_shifts
    assert top.unit == "m" and left + right == pytest.approx(0.0, abs=1e-9)
    # the difference is the change of the parameter on the left arm's samples that moves
    # their predicted depth by +DEPTH_BIAS (its sign too), judged by the model itself
    assert (left - right) * _depth_slope(diagnosis, top.parameter) == pytest.approx(
        DEPTH_BIAS, rel=0.25)
    advice = " ".join(diagnosis.advice)
    assert "the samples of chain left and chain right disagree" in advice
    assert f"a difference of {(left - right) * 1e3:+.3g} mm (left - right)" in advice
    clean = hostpc.diagnose(_arms({}, seed))
    assert not any(i.variable == "chain" for i in clean.check.significant_interactions)
