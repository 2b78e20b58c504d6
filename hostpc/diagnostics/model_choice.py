"""The model chosen by held-out error: `hostpc fit --effects auto`.

On small real sets a richer model often predicts worse: 24 geometry parameters fitted to
23 poses explain the poses they saw and not the next one. The choice is made the way the
user will be judged, on poses the fit never saw:

- the models compared: ``nominal`` (the frames alone: the robot as drawn), ``offsets``
  (the default model: joint zero offsets and the frames), ``offsets + geometry``, and, when
  the ladder of `hostpc diagnose --ladder` (the same function, options and folds) ends on
  another model, the ``ladder``'s: its final model as it stands (generated effects and the
  parameters a step held at nominal included), refitted on every sample;
- each is scored by its pose-grouped held-out error (``hostpc.fitting.folds``; the same
  folds for every model): per pose, the mean squared whitened held-out residual per scalar
  row (1 at the stated noise), averaged over the poses, with its standard error over them;
- with a robust loss (``--loss huber|cauchy``) the score is robust too, by the rule the
  fit's adequacy uses (``robust_kept``): the samples the loss rejects on the default model
  (diagnose's leave-one-out and leave-one-pose-out outliers, refitted with the loss) are
  left out of every model's score and held-out RMS, the same samples for every model. They
  stay in every fit (the loss weighs them); scored, three poses of sixty read 25 mm off
  would decide the choice by how badly each model predicts readings no model should;
- the one-standard-error rule: among the models whose held-out score is within one
  standard error of the best, the one with the fewest free parameters. A model whose fit
  did not converge, or whose fitted geometry is implausible (``adequacy.implausible_geometry``:
  a table length moved by more than 50 mm, as numbers read in the wrong unit make it), is
  listed, never chosen.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import cast

import numpy as np

from hostpc.dataset import Dataset
from hostpc.diagnostics.adequacy import implausible_geometry
from hostpc.diagnostics.candidates import warm_start
from hostpc.diagnostics.robust_kept import KeptSamples, kept_samples
from hostpc.errors import InputError
from hostpc.fitting import FitResult, fit, solve
from hostpc.fitting.fitting import DEFAULT_CV_FOLDS, held_out_by_fold
from hostpc.fitting.folds import pose_groups
from hostpc.fitting.solver import Loss
from hostpc.model.memo import SharedValues
from hostpc.model.problem import build_problem, extend_problem


@dataclass(frozen=True)
class ModelScore:
    """One model of the table. score, standard_error: the held-out mean squared whitened
    residual per scalar row, over poses, and its standard error (None without held-out
    residuals); cv_rms: the held-out position RMS (m); note: why it cannot be chosen ("":
    it can)."""

    name: str
    effects: tuple[str, ...]
    free_parameters: int
    converged: bool
    score: float | None
    standard_error: float | None
    cv_rms: float | None
    note: str = ""

    @property
    def whitened_rms(self) -> float | None:
        return None if self.score is None else math.sqrt(self.score)


@dataclass(frozen=True, eq=False)  # holds arrays: compared by identity (__init__.py)
class ModelChoice:
    """The table (in order of complexity), the chosen model's name and its fit;
    outlier_note: the diagnosis's outlier note (hostpc.diagnostics.advice.outlier_note),
    "" when it found none or did not run; kept: the samples the scores are taken over
    with a robust loss."""

    scores: tuple[ModelScore, ...]
    chosen: str
    fit: FitResult
    folds: int
    outlier_note: str = ""
    #: with a robust loss, the samples its score leaves out (``robust_kept``); None: every
    #: sample is scored
    kept: KeptSamples | None = None

    def table(self) -> list[str]:
        """The table as text lines (mm, whitened)."""
        lines = [f"  {'model':<20} {'free':>5} {'held-out (whitened)':>20} "
                 f"{'held-out RMS':>13}"]
        for s in self.scores:
            mark = "  <- chosen" if s.name == self.chosen else ""
            if s.score is None or s.standard_error is None:
                held = "-"
            else:
                held = f"{s.score:.3f} +- {s.standard_error:.3f}"
            rms = "-" if s.cv_rms is None else f"{s.cv_rms * 1e3:.4f} mm"
            note = f"  ({s.note})" if s.note else ""
            lines.append(f"  {s.name:<20} {s.free_parameters:>5} {held:>20} {rms:>13}"
                         f"{mark}{note}")
        if self.kept is not None:
            lines.append(f"  held out over the {self.kept.n_kept} samples the {self.kept.loss} "
                         f"loss keeps on the offsets model ({self.kept.left_out_text} left "
                         "out: its outliers, as the fit's adequacy is judged)")
        return lines


def _score(result: FitResult, folds: int, left_out: tuple[int, ...] = ()
           ) -> tuple[float | None, float | None, float | None]:
    """The held-out score, its standard error and the held-out RMS (m) of one model, over
    the samples not ``left_out`` (module docstring)."""
    held = held_out_by_fold(result.problem, result.x, ~result.fixed, folds,
                            loss=cast(Loss, result.loss))
    if held is None:
        return None, None, None
    raw, whitened = held
    kept = np.ones(whitened.shape[0], dtype=bool)
    kept[list(left_out)] = False
    groups = pose_groups(result.problem.dataset.samples)[kept]
    per_row = np.mean(whitened[kept]**2, axis=1)
    count = np.bincount(groups)
    per_pose = np.bincount(groups, weights=per_row) / np.maximum(count, 1)
    per_pose = per_pose[count > 0]
    lengths = raw[kept][:, result.problem.length_columns]
    return (float(np.mean(per_pose)),
            float(np.std(per_pose, ddof=1) / math.sqrt(per_pose.size)),
            float(np.sqrt(np.mean(np.sum(lengths**2, axis=1)))))


def _models(dataset: Dataset, plugins: tuple[str | Path, ...], shared: SharedValues
            ) -> list[tuple[str, tuple[str, ...]]]:
    default = build_problem(dataset, None, plugins=plugins, shared=shared).effect_names
    frames = tuple(name for name in default if name != "joint_offsets")
    models = [("nominal", frames), ("offsets", default)]
    if "geometry" not in default:
        models.append(("offsets + geometry", (*default, "geometry")))
    return models


def _on_every_sample(final: FitResult, start: FitResult, loss: Loss, cv_folds: int
                     ) -> FitResult:
    """The ladder's final model refitted on every sample of the dataset (the ladder climbs
    without the diagnosis's outliers; the table compares every model on the same samples
    and folds): its effects, generated ones included; warm-started at the ladder's
    values."""
    added = [t.effect for t in final.problem.terms[len(start.problem.terms):]]
    problem = extend_problem(start.problem, added)
    return solve(problem, x0=warm_start(final, problem), loss=loss, cv_folds=cv_folds)


def choose_model(dataset: Dataset, *, plugins: Iterable[str | Path] = (),
                 cv_folds: int = DEFAULT_CV_FOLDS, ladder: bool = True,
                 loss: Loss = "linear") -> ModelChoice:
    """Fit every model of the table (module docstring) and choose by the one-standard-error
    rule on the pose-grouped held-out score; loss: the robust loss every model (and the
    ladder) is fitted and held out with."""
    plugin_files = tuple(plugins)
    shared = SharedValues()  # the chain and the rig's sensitivity, once for every model
    models = _models(dataset, plugin_files, shared)
    outliers = ""
    fitted: dict[str, FitResult] = {}
    if ladder:
        from hostpc.diagnostics.advice import outlier_note
        from hostpc.diagnostics.pipeline import diagnose

        # the ladder of `hostpc diagnose --ladder`: the same function, options and folds
        diagnosis = diagnose(dataset, plugins=plugin_files, ladder=True, cv_folds=cv_folds,
                             loss=loss)
        outliers = outlier_note(diagnosis.check) if diagnosis.check.outliers else ""
        steps = diagnosis.ladder or ()
        if steps and len(steps) > 1:
            final = _on_every_sample(steps[-1].check.fit, diagnosis.check.fit, loss,
                                     cv_folds)
            if not any(tuple(final.problem.effect_names) == tuple(effects)
                       for _, effects in models):
                models.append(("ladder", final.problem.effect_names))
                fitted["ladder"] = final
    scores: list[ModelScore] = []
    fits: dict[str, FitResult] = {}
    failed: dict[str, str] = {}
    for name, effects in models:
        try:
            fits[name] = fitted.get(name) or fit(dataset, list(effects), plugins=plugin_files,
                                                 cv_folds=cv_folds, shared=shared, loss=loss)
        except InputError as exc:  # e.g. a nominal model with every frame known: nothing free
            failed[name] = f"not fitted: {exc}"
    kept = kept_samples(fits["offsets"]) if "offsets" in fits else None
    left_out = kept.left_out if kept is not None else ()
    for name, effects in models:
        if name in failed:
            scores.append(ModelScore(name, tuple(effects), 0, False, None, None, None,
                                     failed[name]))
            continue
        result = fits[name]
        score, error, cv_rms = (_score(result, cv_folds, left_out) if result.converged
                                else (None, None, None))
        note = "" if result.converged else "did not converge: not chosen"
        if result.converged and score is None:
            note = "too few poses for a held-out score"
        elif result.converged and implausible_geometry(result) is not None:
            note = "implausible geometry (a table length moved by over 50 mm): not chosen"
        scores.append(ModelScore(name, tuple(effects), int(np.count_nonzero(~result.fixed)),
                                 result.converged, score, error, cv_rms, note))
    scored = [s for s in scores
              if s.score is not None and s.standard_error is not None and not s.note]
    if scored:
        best = min(scored, key=lambda s: s.score or math.inf)
        assert best.score is not None and best.standard_error is not None
        limit = best.score + best.standard_error
        within = [s for s in scored if s.score is not None and s.score <= limit]
        chosen = min(within, key=lambda s: (s.free_parameters, s.score or math.inf)).name
    else:  # no held-out score for any: the default model, as without --effects auto
        chosen = "offsets"
    return ModelChoice(tuple(scores), chosen, fits[chosen], cv_folds, outliers, kept)
