"""Generated effects on frames: a laser tracker whose stand settles during the run (its
registration's z drifts linearly in t) is found by the search, the ladder writes "world.z
linear in t" as an effect, adds it, ends adequate at a chi2/dof at most half of where it
started, and the plugin --write-plugins writes reproduces the fit."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from hostpc.dataset import save_dataset
from hostpc.diagnostics import diagnose
from hostpc.diagnostics.auto_effects import generated_sources
from hostpc.fitting import fit
from hostpc.model.effect import Effect, ModelContext
from tests.hostpc.diagnose_support import hidden_world_point, inject

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
    diagnosis = diagnose(path, ladder=True)
    assert diagnosis.ladder is not None
    added = [s.added for s in diagnosis.ladder]
    assert "world_z_with_t" in added
    first, last = diagnosis.ladder[0], diagnosis.ladder[-1]
    assert last.adequate and last.chi2_dof <= 0.5 * first.chi2_dof
    sources = generated_sources(list(t.effect for t in last.check.fit.problem.terms))
    plugin = tmp_path / "world_z_with_t.py"
    plugin.write_text(sources["world_z_with_t"])
    refit = fit(synthetic.dataset, [*last.effects], plugins=[plugin], cv_folds=0)
    assert refit.chi2 == pytest.approx(last.check.fit.chi2, rel=1e-6)
    k = refit.names.index("world_z_with_t.k")
    assert abs(refit.x[k] - SETTLE) < 3 * refit.std[k]
