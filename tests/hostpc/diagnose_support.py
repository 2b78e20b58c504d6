"""Helpers of the diagnostics tests: datasets with a hidden effect and its measured size.

Hidden built-in effects are injected by hostpc.synthesize (by parameter name); effects that
are in no library (defined in a test's plugin file) are injected by adding their signal to a
synthesized dataset's measurements.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from hostpc.dataset import Dataset, RobotDescription, Samples, SphereFrame
from hostpc.fitting.solver import evaluate
from hostpc.kinds.sphere_probe.file_face import probe_blocks
from hostpc.model.effect import Effect
from hostpc.model.layout import Problem
from hostpc.model.measurements.predict import predict
from hostpc.model.problem import build_problem
from hostpc.model.registry import load_plugin_file
from hostpc.synthesize import SyntheticDataset, random_truth, synthesize_stereo_target

N_SAMPLES = 120


def hidden_dataset(hidden: Mapping[str, float], seed: int, n_samples: int = N_SAMPLES
                   ) -> SyntheticDataset:
    """A stereo_target dataset: random zero offsets and frame errors plus ``hidden``."""
    truth = random_truth(np.random.default_rng(50 + seed))
    truth.update(hidden)
    return synthesize_stereo_target(truth, seed=seed, n_samples=n_samples)


def _truth_problem(synthetic: SyntheticDataset, extra: tuple[Effect, ...] = ()
                   ) -> tuple[Problem, np.ndarray]:
    names = list(synthetic.effects)
    instances = None
    if extra:
        from hostpc.model.registry import available_effects, instantiate

        instances = instantiate(names, available_effects()) + list(extra)
        names += [e.name for e in extra]
    problem = build_problem(synthetic.dataset, names, effect_instances=instances)
    x = np.array([synthetic.truth.get(n, 0.0) for n in problem.layout.names])
    return problem, x


def noise_rms(synthetic: SyntheticDataset, extra: tuple[Effect, ...] = ()) -> float:
    """RMS norm (m) of the noise actually drawn: measured minus the true model."""
    problem, x = _truth_problem(synthetic, extra)
    predicted, _ = predict(problem, x, jacobian=False)
    return float(np.sqrt(np.mean(np.sum((problem.measured - predicted) ** 2, axis=1))))


def unabsorbed_signal(dataset: Dataset, signal: np.ndarray) -> float:
    """Whitened RMS per sample of a signal (N, m) that the default model cannot absorb
    (projected off its Jacobian at nominal): the 'sigma' a hidden effect really shows."""
    problem = build_problem(dataset, None)
    whitened = np.einsum("nij,nj->ni", problem.sqrt_information, signal).ravel()
    J = evaluate(problem, np.zeros(problem.layout.size)).jacobian
    assert J is not None
    U = np.linalg.svd(J, full_matrices=False)[0]
    rest = whitened - U @ (U.T @ whitened)
    return float(np.sqrt(np.sum(rest**2) / signal.shape[0]))


def hidden_signal(synthetic: SyntheticDataset, hidden: Mapping[str, float]) -> np.ndarray:
    """(N, m) change of the measurements that the hidden parameters cause."""
    problem, x = _truth_problem(synthetic)
    without = x.copy()
    for k, name in enumerate(problem.layout.names):
        if name in hidden:
            without[k] = 0.0
    return predict(problem, x, False)[0] - predict(problem, without, False)[0]


def inject(synthetic: SyntheticDataset, effect: Effect, values: Mapping[str, float]
           ) -> tuple[SyntheticDataset, np.ndarray]:
    """Add the signal of an effect from no library to a synthesized dataset; returns the new
    synthetic dataset (truth extended) and the signal (N, m)."""
    problem, x = _truth_problem(synthetic)
    extended = build_problem(synthetic.dataset, list(problem.effect_names) + [effect.name],
                             effect_instances=[t.effect for t in problem.terms] + [effect])
    x_extended = np.array([values.get(n, dict(zip(problem.layout.names, x, strict=True))
                                      .get(n, 0.0)) for n in extended.layout.names])
    signal = predict(extended, x_extended, False)[0] - predict(problem, x, False)[0]
    samples = dataclasses.replace(synthetic.dataset.samples,
                                  p=synthetic.dataset.samples.p + signal)
    truth = dict(synthetic.truth)
    truth.update(values)
    return (SyntheticDataset(dataclasses.replace(synthetic.dataset, samples=samples), truth,
                             synthetic.effects), signal)


def plugin_effect(path: Path, name: str) -> Effect:
    """An instance of the effect ``name`` defined in a plugin file."""
    return load_plugin_file(path)[name]()


def sphere_contact_dataset(truth: Mapping[str, float], *, n_samples: int = 60, seed: int = 0,
                           sigma: float = 5e-6) -> Dataset:
    """A sphere_probe dataset whose contacts lie on the sphere under ``truth`` (any effect,
    e.g. ``trigger_latency.latency``), plus Gaussian noise of ``sigma`` on the distance.

    Poses near a wrist-down home pose are moved (Newton, minimum-norm joint steps) until
    the true model predicts exactly the contact distance R + r + noise."""
    from hostpc.kinematics import forward, pose_to_transform
    from hostpc.synthesize import DEFAULT_TOOL, HOME_POSES

    rng = np.random.default_rng(seed)
    home = np.array(HOME_POSES["ur5e"])
    q = home + rng.normal(0.0, 1.0, (n_samples, 6)) * [0.25, 0.15, 0.15, 0.4, 0.4, 0.8]
    T_home = forward(_chain(), home[None, :]).T_base_flange[0]
    tip_home = (T_home @ pose_to_transform(DEFAULT_TOOL.xyz, DEFAULT_TOOL.rpy))[:3, 3]
    radius, stylus = 0.0125, 0.0015
    centre = tip_home + np.array([0.0, 0.0, -0.02])
    samples = Samples(q=q, sigma=np.full(n_samples, sigma), group=np.arange(n_samples) // 5,
                      speed=rng.uniform(0.005, 0.02, n_samples),
                      t=3.0 * np.arange(1, n_samples + 1),
                      approach=np.sign(rng.uniform(-1, 1, (n_samples, 6))))
    dataset = Dataset(method="sphere_probe", robot=RobotDescription(name="ur5e"),
                      frames={"tool": DEFAULT_TOOL, "sphere": SphereFrame(centre, radius)},
                      samples=samples, blocks=probe_blocks(stylus))
    effects = list(dict.fromkeys(["joint_offsets"] + [k.split(".")[0] for k in truth]))
    goal = radius + stylus + rng.normal(0.0, sigma, n_samples)
    for _ in range(20):
        problem = build_problem(dataset, effects)
        x = np.array([truth.get(n, 0.0) for n in problem.layout.names])
        distance, J = predict(problem, x)
        assert J is not None
        # d distance / d q equals d distance / d joint offset
        dq = J[:, 0, problem.layout.effect_slices["joint_offsets"]]
        step = (goal - distance[:, 0])[:, None] * dq / np.sum(dq**2, axis=1, keepdims=True)
        samples = dataclasses.replace(samples, q=samples.q + step)
        dataset = dataclasses.replace(dataset, samples=samples)
        if np.max(np.abs(goal - distance[:, 0])) < 1e-12:
            break
    return dataset


def _chain():  # type: ignore[no-untyped-def]
    from hostpc.kinematics import get_robot

    return get_robot("ur5e")


def coupled_dual_loop(truth: Mapping[str, float], n_per_arm: int = 50, seed: int = 2
                      ) -> Dataset:
    """A dual_loop dataset (hostpc's own model) with a hidden coupling of any neighbouring
    joints, ``joint_coupling.left.k4_3`` (the built-in effect couples only the wrist)."""
    from hostpc.kinds.dual_loop.planning import plan_poses
    from hostpc.kinds.dual_loop.synthesize import make_dataset
    from hostpc.model.effects import JointCoupling
    from hostpc.model.registry import available_effects, instantiate
    from hostpc.synthesize import noisy_measurements

    poses = plan_poses(n_per_arm, np.random.default_rng(seed - 1))
    placeholder = make_dataset(poses, np.zeros((poses.n, 3)),
                               np.broadcast_to(np.eye(3) * 1e-8, (poses.n, 3, 3)))
    names = ["joint_offsets", *placeholder.frames]
    instances = instantiate(names, available_effects()) + [JointCoupling("all")]
    problem = build_problem(placeholder, names + ["joint_coupling"],
                            effect_instances=instances)
    measured, cov = noisy_measurements(problem, truth, np.random.default_rng(seed), 1.0)
    return make_dataset(poses, measured, cov)


def warm_up(n_samples: int, seconds_per_pose: float, swing: float, start: float = 21.0
            ) -> tuple[np.ndarray, np.ndarray]:
    """(t, temperature) (N,) of a run during which the arm warms up by ``swing`` K: an
    exponential approach to its working temperature with a time constant of half the run
    (a cold arm running a shift's program: several K within the first hour)."""
    t = seconds_per_pose * np.arange(1, n_samples + 1, dtype=float)
    tau = t[-1] / 2.0
    rise = (1.0 - np.exp(-t / tau)) / (1.0 - np.exp(-t[-1] / tau))
    return t, start + swing * rise


def warm_stereo_dataset(hidden: Mapping[str, float], seed: int, *, swing: float,
                        seconds_per_pose: float = 30.0, n_samples: int = N_SAMPLES,
                        noise: bool = True) -> SyntheticDataset:
    """As ``hidden_dataset`` (same truth and poses), recorded over a run of
    ``seconds_per_pose`` per pose while the arm warms up by ``swing`` K (``warm_up``);
    ``noise`` False: exact measurements (same poses); ``markers_per_pose`` k: each pose holds
    k consecutive samples (the reflectors seen in it), n_samples // k poses; ``poses``: the
    joint vectors of the poses (rad), instead of random ones."""
    truth = random_truth(np.random.default_rng(50 + seed))
    truth.update(hidden)
    _, temperature = warm_up(n_samples, seconds_per_pose, swing)
    return synthesize_stereo_target(truth, seed=seed, n_samples=n_samples,
                                    seconds_per_pose=seconds_per_pose, temperature=temperature,
                                    noise_scale=1.0 if noise else 0.0)


#: a laser tracker's noise (the world_point method's defaults): 10 um along the beam,
#: 5 urad across it
TRACKER_SIGMA_DISTANCE = 1e-5
TRACKER_SIGMA_ANGLE = 5e-6
TRACKER_MARKERS = {"a": (0.05, 0.0, 0.03), "b": (-0.02, 0.06, 0.05), "c": (0.0, -0.05, 0.04)}


def world_point_truth(rng: np.random.Generator) -> dict[str, float]:
    """Random zero offsets (+-0.5 deg), tracker registration errors (+-2 mm, +-0.5 deg)
    and reflector nest errors (+-1 mm) of a world_point cell."""
    truth = {f"joint_offsets.q{i + 1}": float(np.radians(rng.uniform(-0.5, 0.5)))
             for i in range(6)}
    for axis in "xyz":
        truth[f"world.{axis}"] = float(rng.uniform(-2e-3, 2e-3))
        truth[f"world.r{axis}"] = float(np.radians(rng.uniform(-0.5, 0.5)))
        for marker in TRACKER_MARKERS:
            truth[f"markers.{marker}.{axis}"] = float(rng.uniform(-1e-3, 1e-3))
    return truth


def hidden_world_point(hidden: Mapping[str, float], seed: int, *, swing: float = 0.0,
                       seconds_per_pose: float = 30.0, n_samples: int = N_SAMPLES,
                       noise: bool = True, markers_per_pose: int = 1,
                       poses: np.ndarray | None = None) -> SyntheticDataset:
    """A world_point dataset (a laser tracker 2 m from a ur5e following three reflectors on
    its flange, one per pose in turn): random zero offsets and frame errors plus ``hidden``,
    the tracker's noise drawn from each point's covariance, approach signs of visiting the
    poses in order, and the arm warming up by ``swing`` K over the run (``warm_up``);
    ``noise`` False: exact measurements (same poses); ``markers_per_pose`` k: each pose holds
    k consecutive samples (the reflectors seen in it), n_samples // k poses; ``poses``: the
    joint vectors of the poses (rad), instead of random ones."""
    from hostpc.dataset import FramePose
    from hostpc.kinds.world_point.method import spherical_covariance
    from hostpc.model.measurements.base import UR5E_HOME
    from hostpc.synthesize import approach_signs

    rng = np.random.default_rng(seed)
    truth = world_point_truth(np.random.default_rng(50 + seed))
    truth.update(hidden)
    q = UR5E_HOME + rng.uniform(-1.0, 1.0, (n_samples // markers_per_pose, 6)) * [
        0.8, 0.5, 0.5, 0.8, 0.8, 1.2]
    if poses is not None:  # the caller's poses (n_poses, 6) instead of random ones
        q = np.asarray(poses, float)
    q = np.repeat(q, markers_per_pose, axis=0)
    n_samples = q.shape[0]
    t, temperature = warm_up(n_samples, seconds_per_pose, swing)
    names = list(TRACKER_MARKERS)
    markers = {m: np.array(v) for m, v in TRACKER_MARKERS.items()}
    world = FramePose(xyz=np.array([1.8, -0.6, 0.3]), rpy=np.array([0.0, 0.0, 2.6]))
    fields = {"marker": np.array([names[k % len(names)] for k in range(n_samples)]),
              "mask": np.ones((n_samples, 3))}
    samples = Samples(q=q, p=np.zeros((n_samples, 3)),
                      cov=np.broadcast_to(np.eye(3) * 1e-10, (n_samples, 3, 3)), t=t,
                      temperature=temperature, approach=approach_signs(q, rng), fields=fields)
    dataset = Dataset(method="world_point", robot=RobotDescription(name="ur5e"),
                      frames={"world": world, "markers": markers}, samples=samples)
    effects = list(dict.fromkeys(name.split(".", 1)[0] for name in truth))
    problem = build_problem(dataset, effects)
    x = np.array([truth.get(name, 0.0) for name in problem.layout.names])
    clean, _ = predict(problem, x, jacobian=False)
    cov = spherical_covariance(clean, TRACKER_SIGMA_DISTANCE, TRACKER_SIGMA_ANGLE)
    drawn = np.einsum("nij,nj->ni", np.linalg.cholesky(cov), rng.standard_normal(clean.shape))
    measured = dataclasses.replace(samples, p=clean + (drawn if noise else 0.0), cov=cov)
    return SyntheticDataset(dataclasses.replace(dataset, samples=measured), truth,
                            tuple(effects))


#: families of tests a dataset with nothing hidden can fail, each at the family-wise
#: significance DEFAULT_ALPHA (= ADEQUACY_P_MIN for the chi-square): the chi-square band,
#: the outlier test, the candidates (Bonferroni over them, plus the held-out gain) and the
#: interaction search (Bonferroni over its tests). The ladder adds an effect only when one
#: of the last two fires (a generated effect needs a significant interaction first).
NULL_FAMILIES = 4


def null_alarm_rate() -> float:
    """Upper bound (union bound) of the probability that diagnose --ladder raises any alarm
    on one dataset with nothing hidden."""
    from hostpc.diagnostics import DEFAULT_ALPHA
    from hostpc.diagnostics.adequacy import ADEQUACY_P_MIN

    return (NULL_FAMILIES - 1) * DEFAULT_ALPHA + ADEQUACY_P_MIN


def allowed_alarms(n_datasets: int, rate: float, risk: float = 0.01) -> int:
    """The fewest alarms k such that P(more than k of n | rate) < risk (binomial)."""
    from math import comb

    k = 0
    while sum(comb(n_datasets, j) * rate**j * (1 - rate)**(n_datasets - j)
              for j in range(k + 1, n_datasets + 1)) >= risk:
        k += 1
    return k


def null_alarms(seed: int) -> list[str]:
    """What diagnose --ladder (generated effects on) says is wrong with stereo_target data
    with nothing hidden (seed 100 + seed; the same data as the no-false-alarm test): the
    reasons it is not adequate and the effects the ladder adds (empty: no alarm)."""
    import hostpc

    synthetic = hidden_dataset({}, seed=100 + seed)
    diagnosis = hostpc.diagnose(synthetic.dataset, ladder=True)
    alarms = list(diagnosis.check.adequacy.reasons)
    alarms += [f"ladder adds {s.added}" for s in diagnosis.ladder or () if s.added]
    return alarms
