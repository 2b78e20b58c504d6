"""A hidden built-in effect is found: the default model is judged not adequate, the effect
ranks first among the candidates, and with it added the model is adequate and the held-out
RMS falls to the noise level. Also the same for sphere_probe's trigger latency."""

from __future__ import annotations

import numpy as np
import pytest

from hostpc.diagnostics import diagnose
from tests.hostpc.diagnose_support import (
    hidden_dataset,
    hidden_signal,
    noise_rms,
    sphere_contact_dataset,
    unabsorbed_signal,
)

# realistic magnitudes: each leaves 0.5..4 sigma per sample that the default model cannot
# absorb (asserted below, so a test never passes on a huge signal)
HIDDEN = {
    "joint_compliance": {"joint_compliance.c2": 2.0e-5, "joint_compliance.c3": 2.5e-5},
    "geometry": {"geometry.a2": 3e-4, "geometry.d4": 3e-4},
    "transmission_harmonic": {"transmission_harmonic.sin1_q6": 3e-4,
                              "transmission_harmonic.cos2_q4": 3e-4},
    "backlash": {"backlash.b2": 1.5e-4, "backlash.b3": 1.5e-4},
    "encoder_scale": {"encoder_scale.s2": 1e-3, "encoder_scale.s3": 1e-3},
    "depth_scale": {"depth_scale.s": 2e-3},
}


@pytest.mark.slow
@pytest.mark.parametrize("effect", sorted(HIDDEN))
def test_hidden_builtin_effect_is_found_and_fixed(effect: str) -> None:
    synthetic = hidden_dataset(HIDDEN[effect], seed=1)
    sigma = unabsorbed_signal(synthetic.dataset, hidden_signal(synthetic, HIDDEN[effect]))
    assert 0.5 < sigma < 4.0, f"hidden signal of {sigma:.2f} sigma is not a realistic test"

    diagnosis = diagnose(synthetic.dataset, ladder=True)

    assert not diagnosis.adequate
    first = diagnosis.candidates[0]
    assert first.effect == effect, [c.effect for c in diagnosis.candidates]
    assert first.significant and first.delta_bic < 0
    assert diagnosis.ladder is not None and len(diagnosis.ladder) == 2
    start, fixed = diagnosis.ladder
    assert not start.adequate
    assert fixed.added == effect and fixed.adequate
    assert effect in fixed.effects
    # held-out error falls to the noise level: whitened (every axis by its own noise, 1 is
    # the stated noise) and in mm against the noise actually drawn (the mm RMS is dominated
    # by the depth noise of the far samples, so it need not fall much itself)
    assert fixed.cv_whitened_rms is not None and start.cv_whitened_rms is not None
    assert fixed.cv_whitened_rms < start.cv_whitened_rms
    assert fixed.cv_whitened_rms < 1.15
    noise = noise_rms(synthetic)
    assert fixed.cv_rms is not None and fixed.cv_rms < 1.08 * noise, (fixed.cv_rms, noise)


def test_adding_the_effect_by_name_makes_the_model_adequate() -> None:
    synthetic = hidden_dataset(HIDDEN["joint_compliance"], seed=2)
    before = diagnose(synthetic.dataset, cv_folds=0)
    after = diagnose(synthetic.dataset, effects="+joint_compliance")
    assert not before.adequate and after.adequate
    assert after.check.effects[-1] == "joint_compliance"
    assert after.cv_rms is not None and after.cv_rms < 1.08 * noise_rms(synthetic)
    assert not any(c.significant for c in after.candidates)
    # the compliance found is the hidden one, within its uncertainty
    for joint, truth in ((2, 2.0e-5), (3, 2.5e-5)):
        name = f"joint_compliance.c{joint}"
        assert abs(after.fit.value(name) - truth) < 4 * after.fit.sigma(name)


@pytest.mark.slow
def test_sphere_probe_trigger_latency_is_found() -> None:
    truth = {"joint_offsets.q2": 0.003, "joint_offsets.q3": -0.002, "tool.x": 2e-4}
    hidden = dict(truth, **{"trigger_latency.latency": 1e-3})
    diagnosis = diagnose(sphere_contact_dataset(hidden, seed=0), ladder=True)
    assert not diagnosis.adequate
    assert diagnosis.candidates[0].effect == "trigger_latency"
    assert "depth_scale" not in [c.effect for c in diagnosis.candidates]  # stereo only
    assert diagnosis.ladder is not None and diagnosis.ladder[-1].adequate
    assert diagnosis.ladder[-1].added == "trigger_latency"
    assert any("approach speed" in sentence for sentence in diagnosis.advice)
    document = diagnosis.to_dict()
    assert document["measurement_size"] == 1 and "speed" in [
        p["variable"] for p in document["residuals"]["patterns"]]

    clean = diagnose(sphere_contact_dataset(truth, seed=0), cv_folds=0)
    assert clean.adequate
    assert np.isfinite(clean.chi2_dof)
