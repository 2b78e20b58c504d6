"""The physical-effect plugin contract.

An effect is one small class that names its parameters and acts at one hook point:

- ``joint``: joint-space deltas, ``q_true = q_cmd + joint_delta(ctx, p)``, shape (N, n);
- ``geometry``: deltas of the kinematic table per pose, shape (N, 5n), ordered as the
  kinematic parameter vector of docs/conventions.md (theta, d, a, alpha, beta; joint-minor);
- ``sensor``: a function applied to the ideal sensor-frame measurement (N, 3);
- ``frame``: the unknown frames of a method (tool, target, sphere, ...). Frame effects carry
  no code of their own: each measurement model knows how its frames enter.

Every parameter is a delta from nominal, so ``p = 0`` must give the nominal model (zero delta,
identity sensor function). An effect may supply analytic Jacobians; where it returns ``None``
the model differentiates it numerically (central differences).

A linear joint or geometry effect only has to give its ``basis``: ``delta = basis @ p``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import ClassVar, Literal

import numpy as np

from hostpc.kinematics import Chain

Hook = Literal["joint", "geometry", "sensor", "frame"]


@dataclass(frozen=True)
class ModelContext:
    """What an effect may read about the robot and the samples; constant during a fit.

    chain: the robot's nominal chain; q_cmd: (N, n) commanded joint angles (rad);
    tau: (N, n) gravity load torque at q_cmd (N m), NaN if the robot has no mass data;
    approach: (N, n) sign of the last motion into each pose (+1/-1, 0 where unknown);
    variables: every recorded or derived variable by its contract name (``q1``, ``tau2``,
    ``approach3``, ``t``, ``temperature``, ``speed``, ``depth``, ``extra.NAME``), each (N,);
    NaN on the samples a variable does not exist on (a per-group variable: ``left.q3`` on
    the right arm's samples), which diagnostics leave out when they test it;
    categorical: the variables that are group labels (``marker``, ``chain``,
    ``probe_group``), name -> the level names; their values in ``variables`` are level
    indices 0..k-1 as floats (NaN where unlabelled). Diagnostics test them per level
    ("the residual depends on marker": one marker's mean residual is off), never as numbers.
    """

    chain: Chain
    method: str
    q_cmd: np.ndarray
    tau: np.ndarray
    approach: np.ndarray
    variables: Mapping[str, np.ndarray] = field(default_factory=dict)
    #: name of each column of q_cmd: ("q1", ..., "qn"), or for a kinematic tree
    #: ("head.q1", "head.q2", "left.q1", ...)
    joint_labels: tuple[str, ...] = ()
    #: parameter names of each frame the measurement model estimates, by frame name
    #: (e.g. sphere_probe's tool is a point: ("x", "y", "z"))
    frame_parameters: Mapping[str, tuple[str, ...]] = field(default_factory=dict)
    categorical: Mapping[str, tuple[str, ...]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not self.joint_labels:
            labels = tuple(f"q{i + 1}" for i in range(self.q_cmd.shape[1]))
            object.__setattr__(self, "joint_labels", labels)

    def subset(self, indices: np.ndarray) -> ModelContext:
        """The same context on the samples at ``indices`` (a view for cross-validation)."""
        return replace(self, q_cmd=self.q_cmd[indices], tau=self.tau[indices],
                       approach=self.approach[indices],
                       variables={k: v[indices] for k, v in self.variables.items()})

    def per_joint_names(self, letter: str) -> list[str]:
        """Per-joint parameter names: "c" -> ["c1", ..] (or ["left.c1", ..] on a tree)."""
        names = []
        for label in self.joint_labels:
            prefix, _, joint = label.rpartition(".")
            names.append(f"{prefix + '.' if prefix else ''}{letter}{joint[1:]}")
        return names

    @property
    def n_samples(self) -> int:
        return int(self.q_cmd.shape[0])

    @property
    def n_joints(self) -> int:
        return int(self.q_cmd.shape[1])

    def variable(self, name: str) -> np.ndarray:
        """One variable (N,) by contract name; raises KeyError naming what exists."""
        try:
            return self.variables[name]
        except KeyError:
            known = ", ".join(sorted(self.variables))
            raise KeyError(f"variable {name!r} not in this dataset (have: {known})") from None


class Effect:
    """Base class of every effect. Subclasses set ``name`` and ``hook`` and override the
    methods of their hook. Instances must be cheap and stateless apart from options."""

    name: ClassVar[str]
    hook: ClassVar[Hook]
    description: ClassVar[str] = ""
    #: the measurement kinds the effect applies to (None: all; a plugin effect may name
    #: kinds). A sensor effect acts on a kind's measurement ((N, 3) points of a stereo
    #: camera, (N, 1) contact distances of a probe): a built-in one sets ``()`` and the kinds
    #: it acts on name it (``MeasurementModel.sensor_effects``, ``accepts``).
    methods: ClassVar[tuple[str, ...] | None] = None
    #: the effect depends on the direction each joint last moved (``ctx.approach``):
    #: the planners then reach every joint from both sides (hostpc.planning.approach), so
    #: the effect and the joint's zero offset can be told apart
    approach_dependent: ClassVar[bool] = False
    #: the effect's parameters may be traded against others without a word in the
    #: diagnosis (many deltas of which the data identify a varying subset, none pushed)
    traded_freely: ClassVar[bool] = False
    #: the advice's sentence when this effect is missing and ranked best: what the
    #: residuals follow ("Residuals grow with ..."); ``{j}`` is the joint of the strongest
    #: parameter, ``{parameter}`` its name. None: the advice names the effect and its
    #: description.
    advice: ClassVar[str | None] = None

    @classmethod
    def explains(cls, parameter: str, variable: str, ctx: ModelContext | None = None) -> bool:
        """Whether a residual pattern "parameter varies with variable" (the effect-agnostic
        search's finding) is what this effect models: the variables it suggests for a
        parameter. The advice then names the effect (default: no pattern). ctx: the model's
        context, when the answer depends on the robot (None: assume it does not)."""
        return False

    def parameter_names(self, ctx: ModelContext) -> Sequence[str]:
        """Local parameter names (without the ``<effect>.`` prefix)."""
        raise NotImplementedError

    def parameter_units(self, ctx: ModelContext) -> Sequence[str]:
        """SI unit of each parameter: "rad", "m", "1", "rad/(N m)", ... (display only)."""
        return [self.unit] * len(self.parameter_names(ctx))

    unit: ClassVar[str] = "1"

    # joint hook -------------------------------------------------------------------------
    def joint_delta(self, ctx: ModelContext, p: np.ndarray) -> np.ndarray:
        """(N, n) joint-angle deltas (rad) for parameters p (P,)."""
        return self.basis(ctx) @ p

    def joint_jacobian(self, ctx: ModelContext, p: np.ndarray) -> np.ndarray | None:
        """(N, n, P) derivative of joint_delta by p, or None for a numeric one."""
        return self.basis(ctx) if self.is_linear else None

    # geometry hook ----------------------------------------------------------------------
    def kinematic_delta(self, ctx: ModelContext, p: np.ndarray) -> np.ndarray:
        """(N, 5n) kinematic-table deltas for parameters p (P,)."""
        return self.basis(ctx) @ p

    def kinematic_jacobian(self, ctx: ModelContext, p: np.ndarray) -> np.ndarray | None:
        """(N, 5n, P) derivative of kinematic_delta by p, or None for a numeric one."""
        return self.basis(ctx) if self.is_linear else None

    # sensor hook ------------------------------------------------------------------------
    def sensor_apply(self, ctx: ModelContext, p: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Measurement (N, m) from the ideal one y (N, m) (m = 3: sensor-frame point)."""
        raise NotImplementedError

    def sensor_jacobians(
        self, ctx: ModelContext, p: np.ndarray, y: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray] | None:
        """(d out / d y (N, m, m), d out / d p (N, m, P)), or None for numeric ones."""
        return None

    # linear effects ---------------------------------------------------------------------
    is_linear: ClassVar[bool] = False

    def basis(self, ctx: ModelContext) -> np.ndarray:
        """For linear joint/geometry effects: (N, n, P) or (N, 5n, P) with delta = basis @ p."""
        raise NotImplementedError(f"effect {self.name!r} is not linear: override its delta")


@dataclass(frozen=True)
class EffectTerm:
    """An effect placed in a model: its instance and the slice of the parameter vector."""

    effect: Effect
    names: tuple[str, ...]
    slice: slice

    @property
    def size(self) -> int:
        return self.slice.stop - self.slice.start


def numeric_jacobian(fun, p: np.ndarray, step: float = 1e-6) -> np.ndarray:  # type: ignore[no-untyped-def]
    """Central-difference derivative of fun(p) (any shape S) by p (P,): shape S + (P,)."""
    p = np.asarray(p, dtype=float)
    columns = []
    for k in range(p.size):
        dp = np.zeros_like(p)
        h = step * max(1.0, abs(float(p[k])))
        dp[k] = h
        columns.append((np.asarray(fun(p + dp)) - np.asarray(fun(p - dp))) / (2.0 * h))
    if not columns:
        shape = np.asarray(fun(p)).shape
        return np.zeros(shape + (0,))
    return np.stack(columns, axis=-1)
