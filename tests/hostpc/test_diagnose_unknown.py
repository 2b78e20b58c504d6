"""An effect in no library is pointed at by the effect-agnostic search (the right parameter
and the right variable among the top entries), and adding it as a plugin file makes the
model adequate."""

from __future__ import annotations

from pathlib import Path

import pytest

from hostpc.diagnostics import diagnose
from tests.hostpc.diagnose_support import (
    hidden_dataset,
    inject,
    plugin_effect,
    unabsorbed_signal,
)

WRIST_COUPLING = '''
import numpy as np
from hostpc.model.effect import Effect


class WristCoupling(Effect):
    """Joint 6's angle leaks into joint 5: dq5 = k * sin(q6)."""

    name = "wrist_coupling"
    hook = "joint"
    is_linear = True
    unit = "rad"

    def parameter_names(self, ctx):
        return ["k"]

    def basis(self, ctx):
        basis = np.zeros((ctx.n_samples, ctx.n_joints, 1))
        basis[:, 4, 0] = np.sin(ctx.q_cmd[:, 5])
        return basis
'''

LINK_DRIFT = '''
import numpy as np
from hostpc.kinematics import kin_index
from hostpc.model.effect import Effect


class LinkDrift(Effect):
    """Link length a2 grows with time (warm-up): da2 = rate * t."""

    name = "link_drift"
    hook = "geometry"
    is_linear = True
    unit = "m/s"

    def parameter_names(self, ctx):
        return ["rate"]

    def basis(self, ctx):
        basis = np.zeros((ctx.n_samples, 5 * ctx.n_joints, 1))
        basis[:, kin_index("a", 2, ctx.n_joints), 0] = ctx.variable("t")
        return basis
'''

CASES = {
    # name: (plugin source, parameter values, (parameter, variable) the search must name)
    "wrist_coupling": (WRIST_COUPLING, {"wrist_coupling.k": 1e-3}, ("joint_offsets.q5", "q6")),
    "link_drift": (LINK_DRIFT, {"link_drift.rate": 1.5e-6}, ("geometry.a2", "t")),
}
TOP = 3


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(CASES))
def test_unknown_effect_is_pointed_at_and_fixed_by_a_plugin(name: str, tmp_path: Path) -> None:
    source, values, expected = CASES[name]
    plugin = tmp_path / f"{name}.py"
    plugin.write_text(source)
    synthetic, signal = inject(hidden_dataset({}, seed=1), plugin_effect(plugin, name), values)
    sigma = unabsorbed_signal(synthetic.dataset, signal)
    assert 0.5 < sigma < 4.0, f"hidden signal of {sigma:.2f} sigma is not a realistic test"

    diagnosis = diagnose(synthetic.dataset, cv_folds=0)
    assert not diagnosis.adequate
    top = [(i.parameter, i.variable) for i in diagnosis.interactions[:TOP]]
    assert expected in top, top
    assert diagnosis.interactions[0].significant
    document = diagnosis.to_dict()
    assert {"parameter": expected[0], "variable": expected[1]}.items() <= next(
        i for i in document["interactions"]
        if (i["parameter"], i["variable"]) == expected).items()

    fixed = diagnose(synthetic.dataset, effects=f"+{name}", plugins=[plugin])
    assert fixed.adequate, fixed.check.adequacy.reasons
    assert name in fixed.check.effects
    assert fixed.cv_rms is not None and fixed.cv_rms < diagnosis.rms * 1.05


def test_plugin_effect_not_in_the_model_is_a_candidate(tmp_path: Path) -> None:
    plugin = tmp_path / "wrist.py"
    plugin.write_text(WRIST_COUPLING)
    synthetic, _ = inject(hidden_dataset({}, seed=1), plugin_effect(plugin, "wrist_coupling"),
                          {"wrist_coupling.k": 1e-3})
    diagnosis = diagnose(synthetic.dataset, plugins=[plugin], cv_folds=0, rank_cv_folds=0)
    assert diagnosis.candidates[0].effect == "wrist_coupling"
    assert diagnosis.candidates[0].significant
    best = [s for s in diagnosis.advice if "add wrist_coupling" in s]
    assert best and f"--plugin {plugin}" in best[0]
