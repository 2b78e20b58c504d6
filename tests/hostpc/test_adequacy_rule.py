"""One chi-square rule with one threshold serves diagnose, push and the report; the advice
never says "inside its band" and "below its band" of the same chi2/dof."""

from __future__ import annotations

import dataclasses

import pytest

from hostpc.diagnostics import DEFAULT_ALPHA, diagnose
from hostpc.diagnostics.adequacy import (
    ADEQUACY_P_MIN,
    chi2_adequate,
    chi2_band,
    chi2_dof_upper,
    chi2_p_value,
)
from hostpc.diagnostics.distributions import chi2_isf
from tests.hostpc.diagnose_support import hidden_dataset


def test_one_threshold_and_its_band_edge() -> None:
    assert ADEQUACY_P_MIN == 1e-3 and DEFAULT_ALPHA == ADEQUACY_P_MIN
    for dof in (1, 7, 100, 5000):
        edge = chi2_dof_upper(dof)
        assert chi2_band(dof)[1] == edge
        assert edge * dof == pytest.approx(chi2_isf(ADEQUACY_P_MIN, dof))
        # just inside the edge is adequate, just outside is not: the same rule everywhere
        assert chi2_adequate(edge * dof * (1 - 1e-9), dof)
        assert not chi2_adequate(edge * dof * (1 + 1e-6), dof)
        assert chi2_p_value(edge * dof, dof) == pytest.approx(ADEQUACY_P_MIN, rel=1e-6)
    assert chi2_dof_upper(100) == pytest.approx(149.449 / 100, rel=1e-4)
    assert chi2_adequate(0.0, 10)  # a small chi2 is pessimistic covariances, not model error
    assert not chi2_adequate(1.0, 0)  # nothing to judge


def test_diagnose_uses_the_rule() -> None:
    synthetic = hidden_dataset({}, seed=3, n_samples=40)
    a = diagnose(synthetic.dataset, cv_folds=0, rank_cv_folds=0, interactions=False
                 ).check.adequacy
    assert a.chi2_ok == chi2_adequate(a.chi2, a.dof)
    assert a.chi2_band == chi2_band(a.dof)


def test_pessimistic_covariances_read_consistently() -> None:
    """chi2/dof below its band: the verdict says so (adequate), as does the noise sentence;
    no sentence calls it "inside its band"."""
    synthetic = hidden_dataset({}, seed=4, n_samples=60)
    samples = synthetic.dataset.samples
    pessimistic = dataclasses.replace(synthetic.dataset, samples=dataclasses.replace(
        samples, cov=samples.cov * 4.0))
    diagnosis = diagnose(pessimistic, cv_folds=0, rank_cv_folds=0, interactions=False)
    a = diagnosis.check.adequacy
    assert a.chi2_dof < a.chi2_band[0] and diagnosis.adequate
    verdict, noise = diagnosis.advice[0], diagnosis.advice[1]
    assert "is adequate" in verdict and "below its band" in verdict
    assert "below its band" in noise and "pessimistic" in noise
    assert not any("inside its band" in sentence for sentence in diagnosis.advice)
