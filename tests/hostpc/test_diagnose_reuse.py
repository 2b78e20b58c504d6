"""What diagnose computes once and reuses (issue 28, the quick host): a candidate's fits,
kept on the base problem's memo, are judged afresh at each threshold; a candidate's start
(the model plus the effect at the warm start) is one prediction shared by its fit, its
detectable sizes and the interaction search; the held-out residuals of a problem are kept
for the same x and free parameters. Reused or not, every figure is the one a fresh
computation gives."""

from __future__ import annotations

from dataclasses import fields, is_dataclass
from pathlib import Path

import numpy as np
import pytest

from hostpc.dataset import load_dataset
from hostpc.diagnostics.adequacy import held_out_residuals
from hostpc.diagnostics.candidates import Candidate, try_candidate
from hostpc.diagnostics.detectable import detectable_sizes
from hostpc.diagnostics.interactions import search_interactions
from hostpc.fitting import FitResult, solve
from hostpc.model.effects import Geometry
from hostpc.model.effects.coupling import JointCoupling
from hostpc.model.layout import Problem
from hostpc.model.measurements import predict as predict_module
from hostpc.model.problem import build_problem
from hostpc.model.registry import available_effects

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "ur5e_stereo_hidden_compliance.json"


def _fresh_fit() -> FitResult:
    """The example's default model, fitted on a problem of its own (an empty memo)."""
    return solve(build_problem(load_dataset(EXAMPLE), None), cv_folds=0)


def _figures(candidate: Candidate) -> dict[str, object]:
    return {f.name: getattr(candidate, f.name) for f in fields(candidate) if f.name != "fit"}


def test_a_candidate_tried_again_is_judged_at_its_own_threshold() -> None:
    base = _fresh_fit()
    effect = available_effects()["joint_compliance"]
    strict = try_candidate(base, effect(), cv_folds=5, loss="linear", threshold=1e-30)
    loose = try_candidate(base, effect(), cv_folds=5, loss="linear", threshold=1e-3,
                          base_cv=10.0)
    assert loose.fit is strict.fit  # fitted once
    assert not strict.significant and "not significant" in (strict.not_taken or "")
    assert loose.significant and loose.not_taken is None
    # the held-out test still applies to a reused fit: a better base makes it not taken
    worse = try_candidate(base, effect(), cv_folds=5, loss="linear", threshold=1e-3,
                          base_cv=1e-3)
    assert not worse.significant and "held-out samples worse" in (worse.not_taken or "")
    # every figure as a fresh fit on a problem of its own gives it
    fresh = try_candidate(_fresh_fit(), effect(), cv_folds=5, loss="linear", threshold=1e-3,
                          base_cv=10.0)
    assert fresh.fit is not loose.fit
    assert _figures(fresh) == _figures(loose)
    np.testing.assert_array_equal(fresh.fit.x, loose.fit.x)


def test_a_candidate_is_fitted_again_for_other_folds_or_another_effect_state() -> None:
    base = _fresh_fit()
    effect = available_effects()["joint_compliance"]
    five = try_candidate(base, effect(), cv_folds=5, loss="linear", threshold=1e-3)
    none = try_candidate(base, effect(), cv_folds=0, loss="linear", threshold=1e-3)
    assert none.fit is not five.fit and none.cv_rms is None and five.cv_rms is not None
    wrist = try_candidate(base, JointCoupling("wrist"), cv_folds=0, loss="linear",
                          threshold=1e-3)
    every = try_candidate(base, JointCoupling("all"), cv_folds=0, loss="linear",
                          threshold=1e-3)
    assert every.fit is not wrist.fit
    assert len(every.fit.x) > len(wrist.fit.x)  # "all" couples more neighbouring pairs


def _predictions(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    """A list that grows by one at every prediction with a Jacobian (the real one runs)."""
    calls: list[int] = []
    real = predict_module.predict

    def counted(problem: Problem, x: np.ndarray, jacobian: bool = True
                ) -> tuple[np.ndarray, np.ndarray | None]:
        if jacobian:
            calls.append(x.size)
        return real(problem, x, jacobian)

    for module in ("candidates", "detectable", "interactions"):
        monkeypatch.setattr(f"hostpc.diagnostics.{module}.predict", counted, raising=False)
    monkeypatch.setattr("hostpc.fitting.solver.predict", counted)
    return calls


def test_a_candidates_start_is_one_prediction_for_its_fit_sizes_and_search(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """The detectable sizes of a candidate tried on a fit, and the interaction search's
    geometry columns of that fit, take the candidate fit's start: no prediction of their
    own; and they are the sizes of a fresh computation."""
    base = _fresh_fit()
    registry = available_effects()
    try_candidate(base, registry["joint_compliance"](), cv_folds=0, loss="linear",
                  threshold=1e-3)
    try_candidate(base, Geometry(), cv_folds=0, loss="linear", threshold=1e-3)
    calls = _predictions(monkeypatch)
    sizes = detectable_sizes(base, registry["joint_compliance"](), 1e-4)
    assert calls == []  # the candidate's start, kept
    search_interactions(base, {"q1": base.problem.dataset.samples.q[:, 0]}, 1e-3)
    assert calls == []  # the base fit's evaluation and geometry's start, both kept
    monkeypatch.undo()
    fresh = detectable_sizes(_fresh_fit(), registry["joint_compliance"](), 1e-4)
    assert fresh == sizes


def test_held_out_residuals_are_kept_per_x_and_free_parameters() -> None:
    base = _fresh_fit()
    free = ~base.fixed
    first = held_out_residuals(base.problem, base.x, free, 5)
    again = held_out_residuals(base.problem, base.x.copy(), free.copy(), 5)
    assert first is not None and again is first
    with pytest.raises(ValueError):
        first.raw[0, 0] = 0.0  # read-only: no caller can change what the next one gets
    moved = base.x.copy()
    moved[0] += 1e-6
    other = held_out_residuals(base.problem, moved, free, 5)
    assert other is not None and other is not first
    assert not np.array_equal(other.whitened, first.whitened)
    fresh = held_out_residuals(_fresh_fit().problem, base.x, free, 5)
    assert fresh is not None
    np.testing.assert_array_equal(fresh.raw, first.raw)
    np.testing.assert_array_equal(fresh.whitened, first.whitened)


def _problems(root: object) -> list[Problem]:
    """Every Problem reachable from root through dataclass fields, tuples, lists and dicts
    (not into a problem)."""
    found: dict[int, Problem] = {}
    seen: set[int] = set()
    stack = [root]
    while stack:
        item = stack.pop()
        if id(item) in seen:
            continue
        seen.add(id(item))
        if isinstance(item, Problem):
            found[id(item)] = item
        elif is_dataclass(item) and not isinstance(item, type):
            stack.extend(getattr(item, f.name) for f in fields(item))
        elif isinstance(item, tuple | list):
            stack.extend(item)
        elif isinstance(item, dict):
            stack.extend(item.values())
    return list(found.values())


def test_a_diagnosis_keeps_no_candidate_fits() -> None:
    """Once diagnose returns, the memos of the problems it holds keep no candidate's fit
    (a retained diagnosis was 15-20 % larger)."""
    from hostpc.diagnostics import diagnose

    diagnosis = diagnose(load_dataset(EXAMPLE), ladder=True, interactions=False)
    problems = _problems(diagnosis)
    assert len(problems) > 2  # the model's, its ladder steps', its candidates'
    assert not [key for p in problems for key in p.memo.keys() if key.startswith("candidate ")]
