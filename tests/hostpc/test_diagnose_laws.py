"""Physical laws as candidates: compliance under a payload logged per pose is the load's
weight times its lever arm times the compliance, not an offset linear in the payload. The
generated law candidate is ranked and tested held out like the built-ins, the ladder adds
it, ends adequate at a chi2/dof at most half of where it started, and the plugin it
writes reproduces the fit."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from hostpc.diagnostics import diagnose
from hostpc.diagnostics.auto_effects import generated_sources
from hostpc.fitting import fit
from hostpc.kinematics import forward
from hostpc.model.effect import Effect, ModelContext
from hostpc.synthesize import SyntheticDataset
from tests.hostpc.diagnose_support import hidden_dataset, inject

COMPLIANCE = 4e-5  # rad/(N m) at joint 2; payloads up to 10 kg: up to about 3 mrad


class PayloadBendsJoint2(Effect):
    """Joint 2 bends by c * m * g * (horizontal reach of the flange from joint 2's axis),
    the lever arm taken by finite differences of the flange height (in no library)."""

    name = "payload_bends_q2"
    hook = "joint"

    def parameter_names(self, ctx: ModelContext) -> list[str]:
        return ["c"]

    def joint_delta(self, ctx: ModelContext, p: np.ndarray) -> np.ndarray:
        step = 1e-6
        q = ctx.q_cmd.copy()
        height = forward(ctx.chain, q).T_base_flange[:, 2, 3]
        q[:, 1] += step
        lever = (forward(ctx.chain, q).T_base_flange[:, 2, 3] - height) / step
        delta = np.zeros_like(ctx.q_cmd)
        delta[:, 1] = p[0] * ctx.variable("extra.payload") * -9.81 * lever
        return delta


def payload_world(seed: int) -> SyntheticDataset:
    base = hidden_dataset({}, seed=seed)
    samples = base.dataset.samples
    payload = np.random.default_rng(seed).uniform(0.0, 10.0, len(samples.q))
    logged = dataclasses.replace(samples, extra={**samples.extra, "payload": payload})
    world = SyntheticDataset(dataclasses.replace(base.dataset, samples=logged), base.truth,
                             base.effects)
    return inject(world, PayloadBendsJoint2(), {"payload_bends_q2.c": COMPLIANCE})[0]


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_ladder_adds_the_payload_law(tmp_path: Path, seed: int) -> None:
    synthetic = payload_world(seed)
    diagnosis = diagnose(synthetic.dataset, ladder=True)
    assert diagnosis.ladder is not None
    name = "payload_times_gravity_torque"
    assert name in [s.added for s in diagnosis.ladder], [s.added for s in diagnosis.ladder]
    first, last = diagnosis.ladder[0], diagnosis.ladder[-1]
    assert last.adequate and last.chi2_dof <= 0.5 * first.chi2_dof
    plugin = tmp_path / f"{name}.py"
    plugin.write_text(generated_sources([t.effect for t in last.check.fit.problem.terms])[name])
    # the ladder's model: its effects
    refit = fit(synthetic.dataset, [*last.effects], plugins=[plugin], cv_folds=0)
    assert refit.chi2 == pytest.approx(last.check.fit.chi2, rel=1e-6)
    c2 = refit.names.index(f"{name}.c2")
    assert abs(refit.x[c2] - COMPLIANCE) < 3 * refit.std[c2] + 0.05 * COMPLIANCE
