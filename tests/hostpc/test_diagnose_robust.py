"""One bad sample, very few samples, and the ladder's held-out guard: an outlier is named
(and no effect blamed for it), a candidate the data cannot test is not ranked as evidence,
and the ladder never adds an effect that predicts held-out samples worse."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from hostpc.cli.diagnose import format_diagnosis, ladder_header
from hostpc.cli.main import main
from hostpc.dataset import Dataset, load_dataset, save_dataset
from hostpc.diagnostics import diagnose
from hostpc.diagnostics.advice import advise, noise_sentence
from hostpc.diagnostics.ladder import climb
from hostpc.diagnostics.outliers import deletion_statistics
from hostpc.fitting import fit, solve
from hostpc.fitting.solver import evaluate
from tests.hostpc.diagnose_support import hidden_dataset

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "ur5e_stereo_hidden_compliance.json"


def shifted(dataset: Dataset, sample: int, shift: np.ndarray) -> Dataset:
    """The dataset with one measurement moved by ``shift`` (m)."""
    p = dataset.samples.p.copy()
    p[sample] += shift
    return dataclasses.replace(dataset, samples=dataclasses.replace(dataset.samples, p=p))


def eight_sigma(dataset: Dataset, sample: int) -> Dataset:
    """One misdetection: the sample moved by 8 sigma of its own stated noise (along depth)."""
    L = np.linalg.cholesky(dataset.samples.cov[sample])
    return shifted(dataset, sample, L @ np.array([0.0, 0.0, 8.0]))


def test_one_8_sigma_misdetection_is_an_outlier_and_blames_no_effect() -> None:
    clean = hidden_dataset({}, seed=3).dataset
    diagnosis = diagnose(eight_sigma(clean, 17), cv_folds=0, rank_cv_folds=0)
    # the aggregate chi-square alone would pass it: the outlier test must not
    a = diagnosis.check.adequacy
    assert a.chi2_ok
    assert not diagnosis.adequate
    assert [o.sample for o in diagnosis.outliers] == [17]
    assert 6.5 < diagnosis.outliers[0].sigma < 9.5
    assert a.reasons[0].startswith("sample #17")
    first = diagnosis.advice[0]
    assert first.startswith("Sample #17") and "outlier" in first and "--loss cauchy" in first
    assert not any(c.significant for c in diagnosis.candidates)
    assert not any(i.significant for i in diagnosis.interactions)
    document = json.loads(json.dumps(diagnosis.to_dict(), allow_nan=False))
    assert [(o["sample"], round(o["sigma"], 6)) for o in document["outliers"]] == [
        (17, round(diagnosis.outliers[0].sigma, 6))]
    # the same data without the misdetection: no outlier
    assert diagnose(clean, cv_folds=0, rank_cv_folds=0).to_dict()["outliers"] == []


def test_gross_outlier_neither_hides_nor_fakes_an_effect(capsys: pytest.CaptureFixture[str],
                                                         tmp_path: Path) -> None:
    """One p off by 10 m in the example (hidden compliance): the outlier is named first, and
    the candidates, the search and the ladder - fitted without it - find the compliance and
    nothing else."""
    bad = shifted(load_dataset(EXAMPLE), 10, np.array([0.0, 0.0, 10.0]))
    path = tmp_path / "bad.json"
    save_dataset(bad, path)
    assert main(["diagnose", str(path), "--ladder", "--json"]) == 1  # not adequate
    document = json.loads(capsys.readouterr().out)
    assert [o["sample"] for o in document["outliers"]] == [10]
    assert document["adequate"] is False
    assert document["advice"][0].startswith("Sample #10")
    assert document["candidates"][0]["effect"] == "joint_compliance"
    assert document["candidates"][0]["significant"]
    first = document["interactions"][0]
    assert (first["parameter"], first["variable"]) == ("joint_offsets.q2", "tau2")
    ladder = document["ladder"]
    assert [s["added"] for s in ladder] == [None, "joint_compliance"]
    assert ladder[-1]["adequate"] and ladder[-1]["cv_rms"] < ladder[0]["cv_rms"] < 1e-3
    assert any("without sample #10" in sentence for sentence in document["advice"])
    # the binned residuals are those without the outlier: not every variable is patterned
    patterns = document["residuals"]["patterns"]
    assert sum(p["significant"] for p in patterns) < len(patterns) / 2
    assert len(document["residuals"]["norm"]) == document["n_samples"] == 120


def test_understated_covariance_makes_no_outlier() -> None:
    """The outlier test is scale-free: covariances a constant factor too small fail the
    chi-square, not a sample."""
    synthetic = hidden_dataset({}, seed=4, n_samples=60)
    samples = synthetic.dataset.samples
    understated = dataclasses.replace(synthetic.dataset, samples=dataclasses.replace(
        samples, cov=samples.cov / 9.0))
    diagnosis = diagnose(understated, cv_folds=0, rank_cv_folds=0, interactions=False)
    assert not diagnosis.check.adequacy.chi2_ok and diagnosis.outliers == ()


def test_deletion_statistic_is_the_leave_one_out_residual() -> None:
    """|r|^2 <= d^2 <= |e|^2 with r the fitted whitened residual and e the one a fit without
    the sample predicts (d^2 = r^T (I - H)^-1 r = e^T (I - H) e, H in [0, 1))."""
    result = fit(hidden_dataset({}, seed=5, n_samples=40).dataset, cv_folds=0)
    stats = deletion_statistics(result)
    assert np.all(stats.dfn == 3) and np.all((stats.p_value > 0) & (stats.p_value <= 1))
    everyone = np.arange(40)
    for k in (0, 7, 23):
        alone = solve(result.problem.subset(np.setdiff1d(everyone, [k])), x0=result.x,
                      cv_folds=0)
        e = evaluate(result.problem.subset(np.array([k])), alone.x, jacobian=False).whitened
        r2 = float(np.sum(result.residuals_whitened[k] ** 2))
        assert r2 <= stats.d2[k] * (1 + 1e-9)
        assert stats.d2[k] <= float(np.sum(e**2)) * (1 + 1e-3)


def test_ladder_never_adds_an_effect_that_predicts_held_out_samples_worse() -> None:
    synthetic = hidden_dataset({"joint_compliance.c2": 2.0e-5, "joint_compliance.c3": 2.5e-5},
                               seed=2, n_samples=60)
    diagnosis = diagnose(synthetic.dataset, cv_folds=3, rank_cv_folds=0, interactions=False)
    start = diagnosis.check
    assert start.best_candidate is not None and start.adequacy.cv_whitened_rms is not None
    a = start.adequacy

    def scaled(factor: float) -> object:
        adequacy = dataclasses.replace(a, cv_rms=a.cv_rms * factor, adequate=True,
                                       cv_whitened_rms=a.cv_whitened_rms * factor)
        return lambda fit_: dataclasses.replace(start, adequacy=adequacy)

    steps, stop = climb(start, scaled(1.05))  # significant in-sample, worse held out
    assert len(steps) == 1 and stop is not None
    assert stop.startswith("joint_compliance") and "held-out" in stop
    advice = advise(start, diagnosis.residuals, steps, None, (), ladder_stop=stop)
    assert any(s.startswith("Ladder stopped: joint_compliance") for s in advice)
    steps, stop = climb(start, scaled(0.95))
    assert [s.added for s in steps] == [None, "joint_compliance"] and stop is None


@pytest.mark.parametrize("n_samples", [5, 3])
def test_very_few_samples(n_samples: int, capsys: pytest.CaptureFixture[str],
                          tmp_path: Path) -> None:
    """No meaningless BIC (chi2 -> 0 when a candidate leaves no degrees of freedom), no
    traceback, and a plain statement that the samples are too few."""
    path = tmp_path / "few.json"
    save_dataset(hidden_dataset({}, seed=3, n_samples=n_samples).dataset, path)
    code = main(["diagnose", str(path), "--ladder", "--json"])
    document = json.loads(capsys.readouterr().out)
    assert code == (0 if document["adequate"] else 1)
    candidates = document["candidates"]
    untestable = [c for c in candidates if not c["testable"]]
    assert untestable, "5 samples cannot test every candidate"
    for c in untestable:
        assert c["delta_bic"] is None and c["delta_bic_full"] is None
        assert c["p_value"] is None and not c["significant"]
    testable = [c["testable"] for c in candidates]
    assert testable == sorted(testable, reverse=True)  # not testable ones last
    assert all(c["delta_bic"] > -100 for c in candidates if c["testable"])
    assert any(s.startswith("Too few samples to judge") for s in document["advice"])
    assert main(["diagnose", str(path), "--ladder"]) == code
    text = capsys.readouterr().out
    assert "untestable" in text and "Traceback" not in text
    if n_samples == 3:  # no degrees of freedom left at all
        assert document["dof"] == 0 and document["adequate"] is False
        assert "verdict: cannot judge (too few samples)" in text


def test_noise_ratio_is_labelled_whitened() -> None:
    diagnosis = diagnose(hidden_dataset({}, seed=3, n_samples=40).dataset, cv_folds=0,
                         rank_cv_folds=0, interactions=False)
    sentence = noise_sentence(diagnosis.check)
    assert "Whitened ratio" in sentence and "(ratio" not in sentence
    assert "whitened ratio" in format_diagnosis(diagnosis)


def test_ladder_table_keeps_its_columns_with_huge_values() -> None:
    diagnosis = diagnose(hidden_dataset({}, seed=3, n_samples=40).dataset, cv_folds=0,
                         rank_cv_folds=0, interactions=False, ladder=True)
    assert diagnosis.ladder is not None
    huge = dataclasses.replace(diagnosis.ladder[0], rms=0.9072939, cv_rms=0.9392346,
                               cv_max=9.9999937, cv_whitened_rms=4966.190,
                               chi2_dof=23938569.362)
    small = dataclasses.replace(huge, step=1, added="joint_compliance", rms=2.1e-4,
                                cv_rms=None, cv_max=None, cv_whitened_rms=1.05, chi2_dof=1.1)
    text = format_diagnosis(dataclasses.replace(diagnosis, ladder=(huge, small)))
    lines = text.splitlines()
    header = ladder_header()
    rows = lines[lines.index(header) + 1:lines.index(header) + 3]
    ends = [header.index(name) + len(name) for name in
            ("RMS mm", "held-out", "max", "sigma", "chi2/dof")]
    for row in rows:
        for end in ends:  # every value ends where its column header ends
            assert row[end - 1] != " " and row[end] == " ", (row, end)
    assert "2.394e+07" in rows[0] and "9999.9937" in rows[0]
