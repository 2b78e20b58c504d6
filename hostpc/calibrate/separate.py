"""`hostpc calibrate --resume RUN --separate A,B`: measure the poses that tell two
confounded candidates apart, append them to the run's data, and test the pair again.

The plan (``plan_separation``) comes from the run's fit and the kind's own reachable pool
(``Method.candidates``, whole groups where the kind measures groups: sphere_probe's
orientations), leaving out the poses the run already planned; the poses are chosen by
``hostpc.planning.separate`` on the pair's linearised nested tests
(``hostpc.diagnostics.separation``). The plan is journaled (``{"event": "separate", ...}``)
before anything moves, so a resume measures the same poses and never one twice; they are
fit poses with their own sample indices (``first`` on), so every later fit of the run
includes them. After they are measured the pair is tested again (``retest``) and the
verdict written to ``separation.json`` and journaled (``separated``).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, cast

import numpy as np

from hostpc.calibrate.journal import Journal
from hostpc.diagnostics.candidates import Candidate, check_candidate_names, try_candidate
from hostpc.diagnostics.separation import (
    PairTest,
    measured_rows,
    needed_noncentralities,
    noncentralities,
    pair_model,
    pair_test,
    predicted_power,
)
from hostpc.errors import InputError
from hostpc.files import write_json_atomic
from hostpc.fitting import FitResult
from hostpc.fitting.solver import Loss
from hostpc.methods.base import Method, Plan, RunSettings
from hostpc.model.effect import Effect
from hostpc.model.registry import available_effects
from hostpc.planning.design import per_pose
from hostpc.planning.separate import separating_poses
from hostpc.robots.base import RobotState

SEPARATION_FILE = "separation.json"
#: the most extra groups (or single poses) a separating plan takes
MAX_SEPARATING_GROUPS = 40
#: significance of the pair's tests when the run's settings do not say (diagnose's default)
SEPARATION_ALPHA = 1e-3
#: the power a separating plan is planned for: a separation that misses leaves the user with
#: no decision and a second experiment, so it plans for 95 %, not the 80 % of a detectable
#: size (at 80 % the single-sphere world's separation missed in its seed-3 draw: p = 0.03)
SEPARATION_POWER = 0.95


def parse_separate(text: str, plugins: Sequence[str], run_dir: str | None) -> tuple[str, str]:
    """``A,B`` -> (A, B): two different registered effects (not frames), and only with
    --resume; else one InputError line with the command to use."""
    example = f"hostpc calibrate --resume {run_dir or 'RUN'} --separate A,B"
    if run_dir is None:
        raise InputError(f"--separate needs --resume RUN (it measures more poses for a run "
                         f"already measured): {example}")
    names = [n.strip() for n in text.split(",") if n.strip()]
    if len(names) != 2 or names[0] == names[1]:
        raise InputError(f"--separate {text!r}: name two different candidate effects, "
                         f"e.g. {example} (hostpc diagnose RUN/dataset.json names the "
                         "confounded ones)")
    try:
        check_candidate_names(names, available_effects(tuple(plugins)))
    except InputError as exc:  # its words name diagnose's option: say them as ours
        words = str(exc).removeprefix("--candidates: ").replace(" from the candidates", "")
        raise InputError(f"--separate: {words}; then: {example}") from None
    return names[0], names[1]


@dataclass(frozen=True)
class SeparationPlan:
    """The journaled plan: the pair, the first sample index, the poses (N, n) in visiting
    order and the predicted noncentralities and powers before / after."""

    effects: tuple[str, str]
    first: int
    q: np.ndarray
    predicted: Mapping[str, Any]

    def to_event(self) -> dict[str, Any]:
        return {"effects": list(self.effects), "first": self.first, "q": self.q.tolist(),
                "predicted": dict(self.predicted)}

    @classmethod
    def from_event(cls, event: Mapping[str, Any]) -> SeparationPlan:
        a, b = event["effects"]
        q = np.asarray(event["q"], float)
        return cls((str(a), str(b)), int(event["first"]),
                   q.reshape(q.shape[0], -1) if q.size else np.zeros((0, 0)),
                   dict(event.get("predicted", {})))

    def lines(self) -> list[str]:
        """The plan in words (progress lines)."""
        a, b = self.effects
        p = self.predicted
        if self.q.shape[0] == 0:
            return [f"separate {a} and {b}: no pose of the reachable pool tells them apart"]
        done = "" if p.get("reached") else " (the pool holds no more: short of the power)"
        return [f"separate {a} and {b}: {self.q.shape[0]} extra poses{done}; predicted "
                f"chi-square gain of {a} given {b} {p['lambda_a_before']:.3g} -> "
                f"{p['lambda_a']:.3g} (power {p['power_a']:.2f}), of {b} given {a} "
                f"{p['lambda_b_before']:.3g} -> {p['lambda_b']:.3g} (power {p['power_b']:.2f}) "
                f"at the pair's threshold"]


def journaled_plan(journal: Journal, effects: tuple[str, str]) -> SeparationPlan | None:
    """The plan an earlier session journaled for this pair (either order), or None."""
    for event in reversed(journal.events("separate")):
        if set(event.get("effects", ())) == set(effects):
            return SeparationPlan.from_event(event)
    return None


def _candidates(result: FitResult, effects: tuple[str, str],
                registry: Mapping[str, type[Effect]], alpha: float, loss: Loss
                ) -> tuple[Candidate, Candidate]:
    """Each of the pair fitted on top of the run's model."""
    a, b = (try_candidate(result, registry[name](), cv_folds=0, loss=loss, threshold=alpha)
            for name in effects)
    return a, b


def plan_separation(journal: Journal, method: Method, state: RobotState, plan: Plan,
                    settings: RunSettings, result: FitResult, effects: tuple[str, str],
                    alpha: float = SEPARATION_ALPHA) -> SeparationPlan:
    """The separating poses of ``effects`` for this run (journaled; see the module doc)."""
    known = journaled_plan(journal, effects)
    if known is not None:
        return known
    registry = available_effects(settings.plugins)
    a, b = _candidates(result, effects, registry, alpha, cast(Loss, settings.loss))
    model = pair_model(result, a, b, registry, settings.plugins)
    pool = method.separation_candidates(state, np.random.default_rng(settings.seed))
    used = np.vstack([q for q in (plan.q, plan.q_verify, plan.q_more, plan.q_verify_grown,
                                  *(np.asarray(e["q"], float).reshape(-1, pool.shape[1])
                                    for e in journal.events("separate")))
                      if q is not None and q.size])
    groups = method.pose_groups(pool)
    members = (groups.members() if groups is not None
               else [np.array([i]) for i in range(pool.shape[0])])
    members = [g for g in members if not any(_is_used(pool[i], used) for i in g)]
    measured = measured_rows(result, model)
    blocks = (per_pose(model.blocks(method.design_dataset(pool)), pool.shape[0])
              if pool.shape[0] else np.zeros((0, 1, len(model.layout))))
    needed = needed_noncentralities(model, alpha, SEPARATION_POWER)
    chosen = separating_poses(measured, blocks, members,
                              lambda rows: noncentralities(model, rows), needed,
                              MAX_SEPARATING_GROUPS)
    fit_indices = [r.index for r in journal.records("fit")]
    first = max([plan.q.shape[0] + (0 if plan.q_more is None else plan.q_more.shape[0]),
                 *(i + 1 for i in fit_indices),
                 *(int(e["first"]) + len(e["q"]) for e in journal.events("separate"))])
    predicted = {"lambda_a_before": chosen.before[0], "lambda_b_before": chosen.before[1],
                 "lambda_a": chosen.after[0], "lambda_b": chosen.after[1],
                 "power_a": predicted_power(chosen.after[0], alpha, model.sizes[0]),
                 "power_b": predicted_power(chosen.after[1], alpha, model.sizes[1]),
                 "needed": list(needed), "reached": chosen.reached, "alpha": alpha}
    plan_out = SeparationPlan(effects, first, pool[chosen.indices], predicted)
    journal.event("separate", **plan_out.to_event())
    return plan_out


def _is_used(q: np.ndarray, used: np.ndarray) -> bool:
    return bool(used.size and np.min(np.max(np.abs(used - q[None, :]), axis=1)) < 1e-9)


def untestable(journal: Journal, planned: SeparationPlan, dof: int) -> str | None:
    """Why the pair cannot be tested on what was measured (the plan's prediction does not
    hold), or None: more than half the separating poses lost, or no degree of freedom left
    in the fit (`dof`: the fit's residual degrees of freedom)."""
    n = planned.q.shape[0]
    measured = sum(r.ok for r in journal.records("fit")
                   if planned.first <= r.index < planned.first + n)
    if n and 2 * measured < n:
        return (f"the test could not be done: {n - measured} of {n} separating poses were "
                f"lost (see their skipped reasons in journal.jsonl); the predicted power does "
                "not hold, no verdict")
    if dof <= 0:
        return (f"the test could not be done: the fit has no degree of freedom left "
                f"(dof {dof}), no verdict")
    return None


def retest(journal: Journal, run_dir: Path, result: FitResult, settings: RunSettings,
           effects: tuple[str, str], alpha: float = SEPARATION_ALPHA) -> PairTest:
    """The pair tested again on the run's data with the separating poses; written to
    ``separation.json`` and journaled."""
    registry = available_effects(settings.plugins)
    loss = cast(Loss, settings.loss)
    a, b = _candidates(result, effects, registry, alpha, loss)
    test = pair_test(a, b, registry, alpha=alpha, cv_folds=0, loss=loss)
    document = {**test.to_dict(), "samples": int(result.problem.measured.shape[0]),
                "sentence": test.sentence, "next": next_command(run_dir, test)}
    write_json_atomic(run_dir / SEPARATION_FILE, document)
    journal.event("separated", **{k: v for k, v in document.items() if k != "sentence"})
    return test


def next_command(run_dir: Path, test: PairTest) -> str | None:
    """The command that adds the chosen candidate to the run's model, or None."""
    if test.winner is None:
        return None
    return f"hostpc calibrate --resume {run_dir} --effects +{test.winner}"

