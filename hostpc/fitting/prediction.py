"""Predict a dataset the fit never saw: the held-out test of a second day of data.

``predict(fitted, dataset)`` builds the fit's model (its effects) on the new dataset, sets
every parameter to the fit's value by name and compares predicted with measured sample by
sample; `fitted` is a ``FitResult`` or the ``FittedModel`` of a saved fit. The model is the
fit's whole model: the robot (joint offsets, geometry, any joint-space effect) and the
instrument's frames as fitted, absolute (the fit dataset's nominal frames with the fitted
frame corrections), never the new dataset's own nominal frames (an import estimates those
from the file it reads, so they are registered to that very data). When the instrument was
set up anew (a tracker moved, a target remounted), ``refit_frames`` re-estimates the frame
effects alone on the new data, starting from its own nominal frames, with the robot's
parameters held at the fit's values: the error that remains is the robot model's, not the
set-up's.

Pure numerics: the CLI (`hostpc predict FIT.json DATASET`) reads the files.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hostpc.dataset import Dataset
from hostpc.dataset.model import Frame
from hostpc.errors import InputError
from hostpc.fitting.fitting import fit
from hostpc.fitting.result import FitResult
from hostpc.fitting.solver import evaluate
from hostpc.json_object import JsonObject
from hostpc.model.problem import build_problem


@dataclass(frozen=True)
class FittedModel:
    """What a prediction needs of a fit: its effects, its parameter values by full name
    (SI, rad) and the nominal frames of the dataset it was fitted on (the frame parameters
    are corrections to them; None: unknown, a fit saved before fits recorded them); the part
    of a saved fit (FIT.json) that predicts."""

    effects: tuple[str, ...]
    values: Mapping[str, float]
    frames: Mapping[str, Frame] | None = None

    @classmethod
    def of(cls, result: FitResult) -> FittedModel:
        return cls(tuple(result.problem.effect_names),
                   {n: float(v) for n, v in zip(result.names, result.x, strict=True)},
                   dict(result.problem.dataset.frames))


@dataclass(frozen=True)
class Prediction:
    """A fit's prediction of a dataset, sample by sample.

    measured, predicted, residuals: (N, m) (SI; residual = measured - predicted);
    whitened: (N, m) residuals whitened by each sample's stated covariance;
    length_columns: the components that are lengths (norms in m are taken over them);
    angle_columns: the components that are angles (rad), empty when none are measured;
    refitted: the frame parameters re-estimated on this dataset (empty without
    ``refit_frames``), with their values."""

    measured: np.ndarray
    predicted: np.ndarray
    residuals: np.ndarray
    whitened: np.ndarray
    length_columns: np.ndarray
    angle_columns: np.ndarray
    refitted: Mapping[str, float]

    @property
    def norms(self) -> np.ndarray:
        """(N,) position error of each sample (m)."""
        return np.linalg.norm(self.residuals[:, self.length_columns], axis=1)

    @property
    def rms(self) -> float:
        return float(np.sqrt(np.mean(self.norms**2))) if self.norms.size else math.nan

    @property
    def max(self) -> float:
        return float(np.max(self.norms)) if self.norms.size else math.nan

    @property
    def angle_rms(self) -> float | None:
        """RMS orientation error (rad) where orientation is measured, else None."""
        if not self.angle_columns.size:
            return None
        angles = np.linalg.norm(self.residuals[:, self.angle_columns], axis=1)
        return float(np.sqrt(np.mean(angles**2)))

    @property
    def whitened_rms(self) -> float:
        """RMS whitened residual per scalar component (1 = at the stated noise)."""
        return float(np.sqrt(np.mean(self.whitened**2))) if self.whitened.size else math.nan

    def to_dict(self) -> JsonObject:
        """JSON document (SI units, radians): the summary and every sample's figures."""
        angle = self.angle_rms
        return {
            "n_samples": int(self.measured.shape[0]),
            "rms": self.rms, "max": self.max, "angle_rms": angle,
            "whitened_rms": self.whitened_rms,
            "refitted": dict(self.refitted),
            "samples": [
                {"measured": m.tolist(), "predicted": p.tolist(), "error": float(e)}
                for m, p, e in zip(self.measured, self.predicted, self.norms, strict=True)
            ],
        }


def predict(fitted: FitResult | FittedModel, dataset: Dataset, *,
            refit_frames: bool = False, plugins: Iterable[str | Path] = ()) -> Prediction:
    """The prediction of `dataset` by the fitted model: its effects at its parameter values,
    in the fit's frames (module docstring). With ``refit_frames`` the frames are estimated
    on `dataset` instead, from its own nominal frames. ``plugins``: the Python files that
    define the fit's plugin effects (`hostpc fit --plugin`). A parameter of the model the fit has
    no value for is an InputError, unless it is a frame parameter and ``refit_frames`` is
    set. A model without recorded frames (``FittedModel.frames`` None) predicts only with
    ``refit_frames``: InputError."""
    model = FittedModel.of(fitted) if isinstance(fitted, FitResult) else fitted
    values, effect_names = model.values, model.effects
    if not refit_frames:
        if model.frames is None:
            raise InputError("the fit records no frames (a fit saved before fits recorded "
                             "them): fit again with hostpc fit DATASET --json, or estimate "
                             "the frames on this dataset with --refit-frames")
        dataset = dataclasses.replace(dataset, frames=fits_frames(dataset.frames,
                                                                   model.frames))
    plugins = tuple(plugins)
    problem = build_problem(dataset, list(effect_names), plugins=plugins)
    names = problem.layout.names
    frame_effects = set(problem.frame_names)
    missing = [n for n in names if n not in values
               and not (refit_frames and n.split(".", 1)[0] in frame_effects)]
    if missing:
        listed = ", ".join(missing[:4]) + (" ..." if len(missing) > 4 else "")
        hint = (" (add --refit-frames to estimate the frames on this dataset)"
                if any(n.split(".", 1)[0] in frame_effects for n in missing) else "")
        raise InputError(f"the fit has no value for {listed}: its model does not match "
                         f"this dataset's{hint}")
    # refitting starts the frames at the dataset's own nominal frames (corrections zero)
    x = np.array([0.0 if refit_frames and n.split(".", 1)[0] in frame_effects
                  else float(values.get(n, 0.0)) for n in names])
    refitted: dict[str, float] = {}
    if refit_frames and frame_effects:
        hold = [n for n in names if n.split(".", 1)[0] not in frame_effects]
        result = fit(dataset, list(effect_names), plugins=plugins, hold=hold, x0=x,
                     cv_folds=0, shared=problem.shared)
        x = result.x
        problem = result.problem
        refitted = {n: float(v) for n, v in zip(names, x, strict=True)
                    if n.split(".", 1)[0] in frame_effects}
    evaluation = evaluate(problem, x, jacobian=False)
    units = problem.measurement.residual_units
    angles = np.array([], dtype=int) if units is None else np.array(
        [k for k, unit in enumerate(units) if unit == "rad"], dtype=int)
    return Prediction(measured=problem.measured, predicted=problem.measured - evaluation.raw,
                      residuals=evaluation.raw, whitened=evaluation.whitened,
                      length_columns=problem.length_columns, angle_columns=angles,
                      refitted=refitted)


def fits_frames(own: Mapping[str, Frame], fitted: Mapping[str, Frame]) -> dict[str, Frame]:
    """The dataset's frames with the fit's in their place: every frame the fit has replaces
    the dataset's of that name (named points point by point, so a point only the dataset
    has stays and the fit has no value for it); frames the fit has not stay the dataset's."""
    frames = dict(own)
    for name, value in fitted.items():
        mine = frames.get(name)
        if isinstance(value, Mapping) and isinstance(mine, Mapping) and all(
                isinstance(v, np.ndarray) for v in (*value.values(), *mine.values())):
            frames[name] = {**mine, **value}
        elif name in frames:
            frames[name] = value
    return frames
