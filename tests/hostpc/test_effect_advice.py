"""Advice and residual patterns are carried by the Effect itself: a plugin effect that
declares its advice sentence and the patterns it models (``Effect.advice``,
``Effect.explains``) gets them in the diagnosis, like a built-in effect."""

from __future__ import annotations

from pathlib import Path

from hostpc.diagnostics import diagnose
from hostpc.diagnostics.patterns import pattern_effect
from hostpc.model.registry import available_effects
from tests.hostpc.diagnose_support import hidden_dataset, inject, plugin_effect
from tests.hostpc.test_diagnose_unknown import WRIST_COUPLING

#: test_diagnose_unknown's wrist coupling, declaring its advice and its patterns
ADVISED_COUPLING = WRIST_COUPLING.replace('''    unit = "rad"
''', '''    unit = "rad"
    advice = "Residuals follow the sine of joint 6's angle ({parameter} leaks into joint 5)"

    @classmethod
    def explains(cls, parameter, variable, ctx=None):
        return parameter == "joint_offsets.q5" and variable in ("q6", "humidity")
''')


def _plugin(tmp_path: Path) -> Path:
    assert "advice" in ADVISED_COUPLING
    plugin = tmp_path / "wrist.py"
    plugin.write_text(ADVISED_COUPLING)
    return plugin


def test_the_built_in_effects_name_their_patterns() -> None:
    assert pattern_effect("joint_offsets.q2", "tau2") == "joint_compliance"
    assert pattern_effect("tool.x", "left.approach3") == "backlash"
    assert pattern_effect("joint_offsets.q4", "q4") == "encoder_scale or transmission_harmonic"
    assert pattern_effect("joint_offsets.left.q5", "left.q6") == "joint_coupling"
    assert pattern_effect("tool.z", "depth") == "depth_scale"
    assert pattern_effect("sphere.x", "speed") == "trigger_latency"
    assert pattern_effect("geometry.a2", "t") == "thermal_expansion"
    assert pattern_effect("geometry.alpha2", "t") is None
    assert pattern_effect("joint_offsets.q5", "humidity") is None


def test_a_plugin_effect_names_its_own_pattern(tmp_path: Path) -> None:
    effects = available_effects([_plugin(tmp_path)]).values()
    assert pattern_effect("joint_offsets.q5", "humidity", None, effects) == "wrist_coupling"
    assert pattern_effect("joint_offsets.q4", "humidity", None, effects) is None


def test_a_plugin_effect_that_declares_advice_gets_it_shown(tmp_path: Path) -> None:
    plugin = _plugin(tmp_path)
    synthetic, _ = inject(hidden_dataset({}, seed=1), plugin_effect(plugin, "wrist_coupling"),
                          {"wrist_coupling.k": 1e-3})
    diagnosis = diagnose(synthetic.dataset, plugins=[plugin], cv_folds=0, rank_cv_folds=0)
    assert diagnosis.candidates[0].effect == "wrist_coupling"
    best = [s for s in diagnosis.advice if "add wrist_coupling" in s]
    assert best and best[0].startswith(
        "Residuals follow the sine of joint 6's angle (wrist_coupling.k leaks into joint 5): "
        "add "
        "wrist_coupling"), best
