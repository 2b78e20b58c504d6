"""A built calibration problem as a value: the parameter layout and everything a fit needs.

``hostpc.model.problem.build_problem`` makes one from a dataset; cross-validation folds
(``Problem.subset``) and candidate effects (``hostpc.model.problem.extend_problem``) are
views and extensions of it that reuse its context, gravity torques and whitening instead
of building again from the dataset.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import Protocol

import numpy as np

from hostpc.dataset import Dataset
from hostpc.kinematics import Chain
from hostpc.model.effect import Effect, EffectTerm, ModelContext
from hostpc.model.memo import ProblemMemo, SharedValues


@dataclass(frozen=True)
class SharedError:
    """An error every sample shares (a stereo rig's calibration error), as its measurement
    model states it for the fit's covariance (``hostpc.fitting.shared_errors``).

    sensitivity: (N, m, K) how each measurement moves with the K shared parameters;
    covariance: (K, K) their covariance; floor: (N, m, m) the part of each sample's
    covariance the method added to stand for the shared error (a weighting only), or None."""

    sensitivity: np.ndarray
    covariance: np.ndarray
    floor: np.ndarray | None = None


class MeasurementPredictor(Protocol):
    """What a problem needs of its measurement model (``MeasurementModel`` provides it;
    declared here so that this module does not depend on the models, which depend on it)."""

    @property
    def name(self) -> str: ...

    @property
    def measurement_size(self) -> int: ...

    @property
    def residual_units(self) -> tuple[str, ...] | None: ...

    def frame_parameters(self, dataset: Dataset) -> Mapping[str, tuple[str, ...]]: ...

    def accepts(self, effect: type[Effect]) -> bool: ...

    def predict(self, problem: Problem, x: np.ndarray, jacobian: bool = True
                ) -> tuple[np.ndarray, np.ndarray | None]: ...

    def shared_error(self, problem: Problem) -> SharedError | None: ...


@dataclass(frozen=True)
class ParameterLayout:
    """Which slice of the parameter vector is which parameter.

    names: full names ``<effect>.<name>`` in vector order; units: SI unit of each;
    effect_slices: effect name -> slice.
    """

    names: tuple[str, ...]
    units: tuple[str, ...]
    effect_slices: Mapping[str, slice]

    @property
    def size(self) -> int:
        return len(self.names)

    def index(self, name: str) -> int:
        try:
            return self.names.index(name)
        except ValueError:
            raise KeyError(f"no parameter {name!r} in this model") from None

    def effect_of(self, index: int) -> str:
        return self.names[index].split(".", 1)[0]


@dataclass(frozen=True)
class Problem:
    """Everything a fit needs; constant during the fit.

    measured: (N, m) measurements (read-only, as sqrt_information: the memos cache what is
    derived from them); sqrt_information: (N, m, m) whitening matrices W with
    W^T W = cov^-1, so whitened residuals are W @ (measured - predicted). model: the
    measurement model that predicts them (``hostpc.model.measurements``).
    """

    dataset: Dataset
    chain: Chain
    context: ModelContext
    terms: tuple[EffectTerm, ...]
    layout: ParameterLayout
    measured: np.ndarray
    sqrt_information: np.ndarray
    plugins: tuple[str, ...] = field(default=())
    #: per term: the constant basis of a linear joint/geometry effect (delta = basis @ p),
    #: computed once, or None
    linear_bases: tuple[np.ndarray | None, ...] = field(default=())
    model: MeasurementPredictor | None = None
    #: what the problems of this dataset share (the chain, the rig's point sensitivity):
    #: carried by its views and extensions, handed to another build on request
    shared: SharedValues = field(default_factory=SharedValues, repr=False, compare=False)
    #: this problem's own values (its latest evaluation, its round-off cost): new for every
    #: problem, a view or an extension included
    memo: ProblemMemo = field(init=False, default_factory=ProblemMemo, repr=False,
                              compare=False)

    @property
    def method(self) -> str:
        return self.dataset.method

    @property
    def measurement(self) -> MeasurementPredictor:
        """The measurement model (always set by ``build_problem``)."""
        assert self.model is not None, "build the problem with build_problem"
        return self.model

    @property
    def effect_names(self) -> tuple[str, ...]:
        return tuple(term.effect.name for term in self.terms)

    @property
    def frame_names(self) -> tuple[str, ...]:
        """The frames this problem estimates (its frame effects)."""
        return tuple(t.effect.name for t in self.terms if t.effect.hook == "frame")

    @property
    def length_columns(self) -> np.ndarray:
        """Indices of the measurement components that are lengths (m): the ones residual
        norms in metres are taken over."""
        m = self.measured.shape[1]
        units = None if self.model is None else self.model.residual_units
        if units is None:
            return np.arange(m)
        return np.array([k for k, unit in enumerate(units) if unit == "m"], dtype=int)

    def term(self, name: str) -> EffectTerm | None:
        for term in self.terms:
            if term.effect.name == name:
                return term
        return None

    def subset(self, indices: np.ndarray) -> Problem:
        """The same model on a subset of the samples (for cross-validation): a view that
        takes the rows of the built context, whitening and linear bases, no rebuild."""
        index = np.atleast_1d(np.asarray(indices))
        measured = self.measured[index]
        measured.setflags(write=False)  # as the problem's (build_problem)
        return replace(
            self,
            dataset=self.dataset.with_samples(self.dataset.samples.subset(index)),
            context=self.context.subset(index),
            measured=measured,
            sqrt_information=self.sqrt_information[index],
            linear_bases=tuple(None if b is None else _rows(b, index)
                               for b in self.linear_bases),
        )


def _rows(basis: np.ndarray, index: np.ndarray) -> np.ndarray:
    """Rows ``index`` of a per-sample basis; one shared by all samples (stride 0) stays a
    view of its one matrix."""
    if basis.ndim == 3 and basis.strides[0] == 0:
        rows = np.arange(basis.shape[0])[index]
        return np.broadcast_to(basis[0], (rows.shape[0],) + basis.shape[1:])
    return basis[index]
