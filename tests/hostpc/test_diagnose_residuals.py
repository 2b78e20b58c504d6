"""Residual analysis and the effect-agnostic search, piece by piece."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from hostpc.diagnostics.interactions import modulators, search_interactions
from hostpc.diagnostics.residual_analysis import (
    analyse_residuals,
    analysis_variables,
    is_angle,
    quantiles,
    sorted_distinct,
    usable_variables,
)
from hostpc.fitting import fit
from tests.hostpc.diagnose_support import hidden_dataset


def test_binned_pattern_is_a_number() -> None:
    rng = np.random.default_rng(0)
    n = 300
    v = rng.uniform(-1, 1, n)
    whitened = rng.standard_normal((n, 3))
    patterned = whitened.copy()
    patterned[:, 1] += 0.8 * v  # a clear trend on axis y
    variables = {"q1": v, "approach1": np.sign(rng.uniform(-1, 1, n)),
                 "temperature": np.full(n, 21.0)}
    clean = analyse_residuals(whitened * 1e-4, whitened, variables, alpha=1e-3)
    found = analyse_residuals(patterned * 1e-4, patterned, variables, alpha=1e-3)
    assert {p.variable for p in clean.patterns} == {"q1", "approach1"}  # constant dropped
    assert not any(p.significant for p in clean.patterns)
    q1 = next(p for p in found.patterns if p.variable == "q1")
    assert q1.significant and found.patterns[0].variable == "q1"
    assert np.all(np.diff(q1.mean_whitened[:, 1]) > 0)  # the bin means follow the trend
    assert q1.counts.sum() == n and q1.dof == 6 * 3
    approach = next(p for p in found.patterns if p.variable == "approach1")
    assert approach.counts.size == 2  # a +-1 variable gets one bin per value
    assert found.worst[0].whitened_norm == max(np.linalg.norm(patterned, axis=1))
    assert [w.index for w in found.worst] == list(np.argsort(-np.linalg.norm(patterned,
                                                                             axis=1))[:10])


def test_variables_used_by_the_analysis() -> None:
    measured = np.array([[0.0, 0.0, 0.50], [0.0, 0.0, 0.40], [0.0, 0.0, 0.45]])
    raw = np.array([[0.0, 0.0, 0.01], [0.0, 0.0, -0.02], [0.0, 0.0, 0.0]])
    chosen = analysis_variables({"depth": measured[:, 2], "t": np.arange(3.0)}, measured, raw)
    assert np.allclose(chosen["depth"], [0.49, 0.42, 0.45])  # predicted, not measured
    usable = usable_variables({"a": np.ones(3), "b": np.array([1.0, np.nan, 2.0]),
                               "t": np.arange(3.0)})
    assert list(usable) == ["t"]
    assert is_angle("q3") and is_angle("left.q3") and not is_angle("tau3")
    assert not is_angle("extra.q3x")
    F, basis = modulators("q2", np.linspace(-1, 1, 5))
    assert F.shape == (5, 3) and basis == "linear+harmonic"
    assert np.allclose(F.mean(axis=0), 0.0)
    F, basis = modulators("t", np.arange(5.0))
    assert F.shape == (5, 1) and basis == "linear"


def test_score_equals_the_chi2_drop_of_actually_adding_the_column(tmp_path: Path) -> None:
    """The first-order statistic of "joint_offsets.q2 varies with tau2" is the chi-square the
    model with dq2 = k (tau2 - mean) really gains (the problem is nearly linear)."""
    synthetic = hidden_dataset({"joint_compliance.c2": 2e-5}, seed=6, n_samples=80)
    base = fit(synthetic.dataset, cv_folds=0)
    found, n_tests = search_interactions(base, base.problem.context.variables, alpha=1e-3)
    pair = next(i for i in found if (i.parameter, i.variable) == ("joint_offsets.q2", "tau2"))
    assert pair.dof == 1 and pair.significant
    assert n_tests == len(found)
    plugin = tmp_path / "q2_tau2.py"
    plugin.write_text(
        "import numpy as np\nfrom hostpc.model.effect import Effect\n\n"
        "class Q2Tau2(Effect):\n    name = 'q2_tau2'\n    hook = 'joint'\n"
        "    is_linear = True\n"
        "    def parameter_names(self, ctx):\n        return ['k']\n"
        "    def basis(self, ctx):\n        b = np.zeros((ctx.n_samples, ctx.n_joints, 1))\n"
        "        tau = ctx.variable('tau2')\n        b[:, 1, 0] = tau - tau.mean()\n"
        "        return b\n")
    extended = fit(synthetic.dataset, "+q2_tau2", plugins=[plugin], cv_folds=0)
    drop = base.chi2 - extended.chi2
    assert abs(pair.chi2 - drop) < 0.02 * drop


def test_duplicate_geometry_columns_are_not_listed() -> None:
    """d1 moves everything along z exactly as target.z does: the search names the model's
    own parameter, not an alias the model already spans."""
    synthetic = hidden_dataset({}, seed=7, n_samples=60)
    base = fit(synthetic.dataset, cv_folds=0)
    found, _ = search_interactions(base, base.problem.context.variables, alpha=1e-3)
    parameters = {i.parameter for i in found}
    assert "geometry.d1" not in parameters and "target.z" in parameters
    assert "geometry.a2" in parameters  # a length the default model cannot absorb


def test_quantiles_and_sorted_distinct_give_numpys_values() -> None:
    """The residual bins' own quantile and unique (no numpy.ma import): numpy's values on
    random, rounded (ties) and integer-valued data of every small size."""
    rng = np.random.default_rng(7)
    for trial in range(3000):
        n = int(rng.integers(1, 200))
        values = rng.standard_normal(n) * 10 ** rng.uniform(-8, 8)
        if trial % 3 == 0:
            values = np.round(values, int(rng.integers(0, 3)))
        if trial % 5 == 0:
            values = rng.integers(-3, 4, n).astype(float)
        q = np.linspace(0.0, 1.0, int(rng.integers(2, 12)))
        assert np.array_equal(quantiles(values, q), np.quantile(values, q))
        assert np.array_equal(sorted_distinct(values), np.unique(values))
