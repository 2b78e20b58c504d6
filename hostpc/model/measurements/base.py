"""The measurement-model plugin contract: what an instrument sees, and its derivative.

A measurement model is one class (a subclass of ``MeasurementModel``) registered by name
(``hostpc.model.measurements.registry``). Its file face
(``hostpc.dataset.measurement_kind``: frames and
their kinds, sample fields, reading and writing) says what a dataset of its method holds;
here it adds what a fit needs:

- ``frame_effects``: the frames the fit may estimate, each with its parameter names (an
  effect named like the frame; built-in frame effects are reused, others made on the fly);
  ``default_frames``: the ones estimated by default unless the dataset marks them known;
- ``own_frame_effects``, ``sensor_effects`` and ``accepts(effect)``: which effects its frames
  and its measurement take, declared by the kind (the generic layers hold no kind names);
- ``measurement_size`` m and ``measurements(dataset) -> (measured (N, m),
  sqrt_information (N, m, m))`` (the whitening W with W^T W = cov^-1);
- ``chain(dataset)``, ``check(dataset, chain)`` and ``context(dataset, chain)``: the robot
  and the ModelContext (contract variables for diagnostics), computed once per problem;
- ``predict(problem, x, jacobian) -> (prediction (N, m), d prediction / dx (N, m, P))``
  with analytic Jacobians (the contract test checks them against finite differences);
- ``shared_error(problem)``: an error shared by every sample (a stereo rig's calibration):
  how it moves the measurements, its covariance, the floor the method added for it
  (``SharedError``), for the fit's covariance (default: none);
- ``example(rng) -> Dataset``: a small plausible dataset of this method, which the contract
  test fits, differentiates and writes to a file and back.

The shape follows gtsam's NoiseModelFactor and theseus' CostFunction: error, Jacobians,
dimension and weight kept apart. The dataset, fitting and diagnostics layers never branch on
a method's name; they ask its model.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import ClassVar

import numpy as np

from hostpc.dataset import Dataset
from hostpc.dataset.measurement_kind import MeasurementKind
from hostpc.errors import InputError
from hostpc.kinematics import Chain, forward
from hostpc.kinematics.rotations import pose_to_transform
from hostpc.model.context import serial_chain, serial_context
from hostpc.model.effect import Effect, ModelContext
from hostpc.model.layout import Problem, SharedError

POSE = ("x", "y", "z", "rx", "ry", "rz")
POINT = ("x", "y", "z")


class MeasurementModel(MeasurementKind):
    """Base class of every measurement model (see the module docstring)."""

    frame_effects: ClassVar[Mapping[str, tuple[str, ...]]] = {}
    default_frames: ClassVar[tuple[str, ...]] = ()
    measurement_size: ClassVar[int] = 3
    #: SI unit of each measurement component; None: all lengths (m). RMS and max residual
    #: norms in m are taken over the length components only (world_pose: x, y, z).
    residual_units: ClassVar[tuple[str, ...] | None] = None
    #: frame effects of its own (a class per frame with its description and parameters),
    #: for frames no built-in frame effect covers (dual_loop's camera, arm bases and
    #: targets); the effect registry lists them with the built-ins. A frame with none gets
    #: an effect made on the fly.
    own_frame_effects: ClassVar[tuple[type[Effect], ...]] = ()
    #: the kind-specific sensor effects (``Effect.methods == ()``) that act on this kind's
    #: measurement, by name (depth_scale on a stereo point, trigger_latency on a contact)
    sensor_effects: ClassVar[tuple[str, ...]] = ()

    @classmethod
    def accepts(cls, effect: type[Effect]) -> bool:
        """Whether ``effect`` may be in a model of this kind: an effect for every kind
        (``methods`` None), one that names this kind in its ``methods`` (a plugin's), or a
        kind-specific one this kind names in ``sensor_effects``."""
        return (effect.methods is None or cls.name in effect.methods
                or effect.name in cls.sensor_effects)

    # the robot and the context ----------------------------------------------------------
    def chain(self, dataset: Dataset) -> Chain:
        """The nominal chain the fit works on (default: the serial robot of the dataset)."""
        return serial_chain(dataset)

    def check(self, dataset: Dataset, chain: Chain) -> None:
        """Validate the samples against the chain (default: the joint count)."""
        if dataset.n_joints != chain.n:
            raise InputError(f"samples have {dataset.n_joints} joint angles but robot "
                             f"{chain.name!r} has {chain.n}")

    def frame_parameters(self, dataset: Dataset) -> Mapping[str, tuple[str, ...]]:
        """Parameter names of each estimable frame (default: ``frame_effects``)."""
        return self.frame_effects

    def context(self, dataset: Dataset, chain: Chain) -> ModelContext:
        """What effects and diagnostics may read (default: the serial robot's context)."""
        return serial_context(dataset, chain, self.frame_parameters(dataset))

    # the measurement --------------------------------------------------------------------
    def measurements(self, dataset: Dataset) -> tuple[np.ndarray, np.ndarray]:
        """(measured (N, m), sqrt_information (N, m, m)); default: a 3-D point ``p`` with
        its covariance ``cov``."""
        return point_measurements(dataset)

    def predict(self, problem: Problem, x: np.ndarray, jacobian: bool = True
                ) -> tuple[np.ndarray, np.ndarray | None]:
        """Predicted measurements (N, m) and their derivative by x (N, m, P) (or None)."""
        raise NotImplementedError

    # the instrument's shared error (hostpc.fitting.shared_errors) ----------------------
    def shared_error(self, problem: Problem) -> SharedError | None:
        """The instrument's error shared by every sample of the problem's dataset (e.g. the
        stereo rig's, from its ``rig_uncertainty`` block), or None (default: the instrument
        declares none)."""
        return None

    @classmethod
    def example(cls, rng: np.random.Generator) -> Dataset:
        """A small dataset of this method at plausible poses (measurements may be zeros)."""
        raise NotImplementedError(f"measurement model {cls.name!r} gives no example dataset")


def point_measurements(dataset: Dataset) -> tuple[np.ndarray, np.ndarray]:
    """Measured 3-D points ``p`` (N, 3) and W = L^-1 for ``cov`` = L L^T (N, 3, 3)."""
    samples = dataset.samples
    if samples.p is None or samples.cov is None:
        raise InputError(f"method {dataset.method!r}: samples need p and cov")
    cov = np.asarray(samples.cov, dtype=float)
    return np.asarray(samples.p, dtype=float), whitening(cov)


def whitening(cov: np.ndarray) -> np.ndarray:
    """W (N, m, m) with W^T W = cov^-1 for covariances (N, m, m): W = L^-1, cov = L L^T."""
    L = np.linalg.cholesky(cov)
    eye = np.broadcast_to(np.eye(cov.shape[-1]), cov.shape)
    return np.asarray(np.linalg.solve(L, eye))


#: a UR5e home pose and a camera-like tool, for the example datasets
UR5E_HOME = np.array([0.0, -1.9, 1.9, -1.6, -1.5708, 0.0])
EXAMPLE_TOOL_XYZ = np.array([0.0, 0.045, 0.06])
EXAMPLE_TOOL_RPY = np.array([0.0, 0.0, np.pi / 2])


def example_poses(chain: Chain, home: np.ndarray, n: int, rng: np.random.Generator,
                  spread: float = 0.3) -> np.ndarray:
    """n joint vectors (n, chain.n) around ``home`` (rad), uniform within +-spread."""
    return np.asarray(home, dtype=float) + rng.uniform(-spread, spread, (n, chain.n))


def point_ahead(chain: Chain, home: np.ndarray, tool: np.ndarray, rpy: np.ndarray,
                depth: float) -> np.ndarray:
    """The point ``depth`` m along the tool's z axis at the home pose (base frame, m)."""
    T_base_flange = forward(chain, np.asarray(home, dtype=float)[None, :]).T_base_flange[0]
    T_base_tool = T_base_flange @ pose_to_transform(tool, rpy)
    return np.asarray(T_base_tool[:3, 3] + depth * T_base_tool[:3, 2])
