"""Generated effects on frames: a laser tracker whose stand settles during the run (its
registration's z drifts linearly in t), a reflector knocked partway through the run, and
a stereo camera's target that creeps: the search finds the frame parameter varying with t,
the ladder writes it as an effect (a line or a step), adds it, ends adequate at a chi2/dof
at most half of where it started, and the plugin --write-plugins writes reproduces the
fit."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from hostpc.dataset import Dataset, save_dataset
from hostpc.diagnostics import diagnose
from hostpc.diagnostics.auto_effects import generated_sources
from hostpc.diagnostics.diagnosis import Diagnosis
from hostpc.fitting import FitResult, fit
from hostpc.model.effect import Effect, ModelContext
from tests.hostpc.diagnose_support import (
    hidden_world_point,
    inject,
    warm_stereo_dataset,
)

SETTLE = 5e-8  # m per second: the tracker stand sinks 50 um in 1000 s


class StandSettles(Effect):
    """The instrument frame's z moves linearly with time (in no library)."""

    name = "stand_settles"
    hook = "sensor"
    methods = ("world_point",)

    def parameter_names(self, ctx: ModelContext) -> list[str]:
        return ["k"]

    def sensor_apply(self, ctx: ModelContext, p: np.ndarray, y: np.ndarray) -> np.ndarray:
        out = np.array(y, dtype=float)
        t = ctx.variable("t")
        out[:, 2] += p[0] * (t - t[0])
        return out


@pytest.mark.parametrize("seed", [1, 2, 3, 4])
def test_ladder_writes_the_drifting_tracker_frame(tmp_path: Path, seed: int) -> None:
    synthetic, _ = inject(hidden_world_point({}, seed=seed), StandSettles(),
                          {"stand_settles.k": SETTLE})
    path = tmp_path / "settle.json"
    save_dataset(synthetic.dataset, path)
    refit = closes(diagnose(path, ladder=True), "world_z_with_t", synthetic.dataset,
                   tmp_path)
    k = refit.names.index("world_z_with_t.k")
    assert abs(refit.x[k] - SETTLE) < 3 * refit.std[k]


def closes(diagnosis: Diagnosis, name: str, dataset: Dataset, tmp_path: Path) -> FitResult:
    """Assert the ladder added ``name`` and ended adequate at half its starting chi2/dof,
    and that the plugin source of ``name`` reproduces the final fit; return the refit."""
    assert diagnosis.ladder is not None
    added = [s.added for s in diagnosis.ladder]
    assert name in added, added
    first, last = diagnosis.ladder[0], diagnosis.ladder[-1]
    assert last.adequate and last.chi2_dof <= 0.5 * first.chi2_dof
    sources = generated_sources([t.effect for t in last.check.fit.problem.terms])
    plugin = tmp_path / f"{name}.py"
    plugin.write_text(sources[name])
    refit = fit(dataset, [*last.effects], plugins=[plugin], cv_folds=0)
    assert refit.chi2 == pytest.approx(last.check.fit.chi2, rel=1e-6)
    return refit


KNOCK = 3e-4  # m: reflector b's nest pushed 0.3 mm along the flange's x


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_ladder_writes_the_knocked_marker_as_a_step(tmp_path: Path, seed: int) -> None:
    before = hidden_world_point({}, seed=seed)
    shifted = before.truth["markers.b.x"] + KNOCK
    after = hidden_world_point({"markers.b.x": shifted}, seed=seed)  # same poses and noise
    samples = before.dataset.samples
    t = np.asarray(samples.t, float)
    knocked = (t > t[len(t) // 2]) & (np.asarray(samples.fields["marker"]) == "b")
    p = np.where(knocked[:, None], after.dataset.samples.p, samples.p)
    dataset = dataclasses.replace(before.dataset, samples=dataclasses.replace(samples, p=p))
    name = "markers_b_x_step_in_t"
    refit = closes(diagnose(dataset, ladder=True), name, dataset, tmp_path)
    k = refit.names.index(f"{name}.k")
    assert abs(refit.x[k] - KNOCK) < 3 * refit.std[k] + 0.05 * KNOCK


CREEP = 8e-4  # m: the stereo camera's target creeps 0.8 mm along the base z over the run


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_ladder_writes_the_creeping_stereo_target(tmp_path: Path, seed: int) -> None:
    start = warm_stereo_dataset({}, seed=seed, swing=0.0)
    moved = warm_stereo_dataset({"target.z": start.truth["target.z"] + CREEP}, seed=seed,
                                swing=0.0)
    samples = start.dataset.samples
    t = np.asarray(samples.t, float)
    share = ((t - t[0]) / (t[-1] - t[0]))[:, None]
    p = samples.p + share * (moved.dataset.samples.p - samples.p)
    dataset = dataclasses.replace(start.dataset, samples=dataclasses.replace(samples, p=p))
    refit = closes(diagnose(dataset, ladder=True), "target_z_with_t", dataset, tmp_path)
    k = refit.names.index("target_z_with_t.k")
    rate = CREEP / (t[-1] - t[0])
    assert abs(refit.x[k] - rate) < 3 * refit.std[k] + 0.05 * rate
