"""Close the loop without code: the ladder turns a significant "parameter varies with
variable" pattern that no built-in effect models into an effect, adds it when it wins on
held-out samples, and --write-plugins writes it as a plugin file that reproduces the fit."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from hostpc.cli.main import main
from hostpc.dataset import load_dataset, save_dataset
from hostpc.diagnostics import diagnose
from hostpc.fitting import fit
from hostpc.model.effect import Effect, ModelContext
from tests.hostpc.diagnose_support import hidden_dataset, inject

DRIFT = 1.5e-6  # rad per second: joint 3's zero creeps during the run


class ZeroDrift(Effect):
    """Joint 3's zero moves linearly with time (in no library)."""

    name = "zero_drift"
    hook = "joint"
    is_linear = True

    def parameter_names(self, ctx: ModelContext) -> list[str]:
        return ["k"]

    def basis(self, ctx: ModelContext) -> np.ndarray:
        basis = np.zeros((ctx.n_samples, ctx.n_joints, 1))
        t = ctx.variable("t")
        basis[:, 2, 0] = t - t.mean()
        return basis

    def joint_delta(self, ctx: ModelContext, p: np.ndarray) -> np.ndarray:
        return np.einsum("njp,p->nj", self.basis(ctx), p)


def test_ladder_builds_the_missing_effect_and_writes_it(tmp_path: Path,
                                                        capsys: pytest.CaptureFixture[str]
                                                        ) -> None:
    synthetic, _ = inject(hidden_dataset({}, seed=4), ZeroDrift(), {"zero_drift.k": DRIFT})
    path = tmp_path / "drift.json"
    save_dataset(synthetic.dataset, path)
    diagnosis = diagnose(path, ladder=True)
    assert not diagnosis.adequate and diagnosis.ladder is not None
    added = [s.added for s in diagnosis.ladder]
    assert added[0] is None and added[1] in ("q3_with_t", "q3_with_temperature")
    assert len(added) == 2 and diagnosis.ladder[-1].adequate
    name = added[1]
    assert list(diagnosis.generated_effects) == [name]
    final = diagnosis.ladder[-1].check.fit
    # the file --write-plugins writes is the effect that was fitted
    plugins = tmp_path / "plugins"
    code = main(["diagnose", str(path), "--ladder", "--write-plugins", str(plugins)])
    assert code == 1  # the model named (the default) is not adequate
    written = plugins / f"{name}.py"
    assert written.is_file() and f"plugin written to {written}" in capsys.readouterr().out
    refit = fit(load_dataset(path), f"+{name}", plugins=[written], cv_folds=0)
    assert refit.chi2 == pytest.approx(final.chi2, rel=1e-6)
    k = refit.names.index(f"{name}.k")
    per_unit = DRIFT if name.endswith("_t") else DRIFT / 0.002  # temperature: 0.002 K/s
    assert abs(refit.x[k] - per_unit) < 3 * refit.std[k]


def test_write_plugins_needs_the_ladder(tmp_path: Path,
                                        capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "plain.json"
    save_dataset(hidden_dataset({}, seed=1, n_samples=30).dataset, path)
    assert main(["diagnose", str(path), "--write-plugins", str(tmp_path / "p")]) == 2
    assert "--write-plugins needs --ladder" in capsys.readouterr().err
