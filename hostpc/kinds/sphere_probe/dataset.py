"""sphere_probe dataset and solve: contact records -> ``Dataset`` -> ``FitResult``.

One sample per contact (latched q, sigma, group, speed, approach, t); the closed-form
initial estimates (S4, S7, S8-S9; ``sphere_geometry``) become the nominal frames, so
``hostpc fit`` starts the joint solve from them. The solve (S11-S13) is ``hostpc.fit`` with
the usual effect plugins: joint offsets, P_b and P_t together (plus ``trigger_latency`` or
any other effect the data asks for). Units SI (m, rad, s); frames per docs/conventions.md.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import replace
from typing import Any

import numpy as np

from hostpc.dataset import Dataset, FramePose, RobotDescription, Samples, SphereFrame
from hostpc.dataset.model import Frame
from hostpc.errors import InputError
from hostpc.fitting import FitResult, fit
from hostpc.json_object import JsonObject
from hostpc.kinds.sphere_probe.acquisition import ContactRecord
from hostpc.kinds.sphere_probe.file_face import probe_blocks, reference_sphere, stylus_radius
from hostpc.kinds.sphere_probe.planning.geometry import (
    MIN_POINTS_KNOWN_RADIUS,
    InitialEstimate,
    SphereFitError,
    fit_sphere,
    initial_estimate,
)
from hostpc.kinds.sphere_probe.planning.setup import METHOD, ProbeSetup
from hostpc.kinematics import Chain, forward, point_jacobian, screws


def build_dataset(robot_name: str, setup: ProbeSetup, records: Sequence[ContactRecord],
                  *, estimate: bool = True, extra: JsonObject | None = None,
                  start_frames: Mapping[str, np.ndarray] | None = None) -> Dataset:
    """The sphere_probe dataset of the contacts that touched (missed ones are listed in
    ``extra_fields["sphere_probe"]["missed"]``).

    estimate: replace the unknown nominal frames by the closed-form initial estimate (S4,
    S7, S8-S9), so the joint solve starts from it; the CAD nominals are kept in
    ``extra_fields["sphere_probe"]["nominal_frames"]``. Each sample's ``speed`` is the
    approach speed along the contact normal (``normal_speeds``), the controller's tip speed
    is kept as ``extra.tip_speed``, and ``sigma`` follows from both (``contact_sigma``).
    start_frames: ``{"tool": P_t, "sphere": P_b}`` to use as the nominal frames instead of
    an estimate from these records (a verification set must share the fit's nominals);
    the contact normals then come from these frames without a preliminary fit.
    """
    touched = [r for r in records if r.contact and r.q_latched is not None]
    missed = [{"group": r.group, "index": r.index, "reason": r.reason}
              for r in records if not r.contact]
    if not touched:
        raise InputError("no contact was recorded: nothing to calibrate")
    q = np.array([r.q_latched for r in touched])
    tip_speed = np.array([np.nan if r.speed is None else r.speed for r in touched])
    samples = Samples(
        q=q, sigma=setup.contact_sigma(tip_speed), group=np.array([r.group for r in touched]),
        speed=tip_speed, approach=np.array([r.approach for r in touched]),
        t=np.array([r.t for r in touched]), extra={"tip_speed": tip_speed})
    tip = setup.tip if start_frames is None else np.asarray(start_frames["tool"], float)
    centre = (setup.sphere_centre if start_frames is None
              else np.asarray(start_frames["sphere"], float))
    frames: dict[str, Frame] = {
        "tool": FramePose(xyz=tip, rpy=np.zeros(3)),
        "sphere": SphereFrame(centre, setup.sphere_radius),
    }
    info: JsonObject = {
        "missed": missed,
        "nominal_frames": {"tip": setup.tip.tolist(),
                           "sphere_centre": setup.sphere_centre.tolist()},
        "repeatability": setup.repeatability, "latency_jitter": setup.latency_jitter,
        "io_line": setup.io_line,
    }
    dataset = Dataset(method=METHOD, robot=RobotDescription(name=robot_name), frames=frames,
                      samples=samples, known=setup.known,
                      blocks=probe_blocks(setup.stylus_radius),
                      extra_fields={"sphere_probe": info, **(extra or {})})
    if estimate and start_frames is None:
        dataset, guess = with_initial_estimate(dataset)
        info["initial_estimate"] = {
            "tip": guess.tip.tolist(), "sphere_centre": guess.sphere_centre.tolist(),
            "patent_tip": guess.patent_tip.tolist(),
            "patent_sphere_centre": guess.patent_sphere_centre.tolist(), "rms": guess.rms,
        }
    directions = [r.direction for r in touched]
    if all(d is not None for d in directions) and np.all(np.isfinite(tip_speed)):
        speed = normal_speeds(dataset, np.array(directions), tip_speed,
                              preliminary_fit=start_frames is None)
        samples = replace(dataset.samples, speed=speed, sigma=setup.contact_sigma(speed))
        dataset = dataset.with_samples(samples)
    return replace(dataset, extra_fields={**dataset.extra_fields, "sphere_probe": info})


def normal_speeds(dataset: Dataset, directions: np.ndarray, tip_speed: np.ndarray, *,
                  preliminary_fit: bool = True) -> np.ndarray:
    """(N,) approach speed along the contact normal (m/s, > 0 toward the centre).

    A late latch moves the tip ``latency * v`` along its direction of travel, which changes
    the tip-to-centre distance by ``latency * v . (-u)`` (u: unit normal from the sphere
    centre to the tip): that normal component, not the tip speed, is what the
    ``trigger_latency`` effect multiplies. directions: (N, n) unit joint-space directions
    of the guarded moves; tip_speed: (N,) the controller's tip speed (m/s). The geometry
    comes from a preliminary fit (joint offsets and frames, no cross-validation) of the
    dataset, so the contact normals are accurate to the fit's residuals (preliminary_fit
    False, a verification set: the dataset's nominal tip and the joints as latched, and
    the sphere centre these contacts touched, fitted with the known radius, since the
    nominal one is off by whatever joint error the latched joints still carry).
    """
    chain = robot_chain_of(dataset)
    q = np.asarray(dataset.samples.q, float).copy()
    if preliminary_fit:
        preliminary = fit(dataset, cv_folds=0)
        frames = frames_from_result(preliminary)
        if "joint_offsets" in preliminary.problem.layout.effect_slices:
            q = q + preliminary.effect_values("joint_offsets")[None, :]
    else:
        frames = {"tool": np.asarray(dataset.pose("tool").xyz, float),
                  "sphere": np.asarray(reference_sphere(dataset).center, float)}
    poses = forward(chain, q)
    T = poses.T_base_flange
    tip = np.einsum("nij,j->ni", T[:, :3, :3], frames["tool"]) + T[:, :3, 3]
    if not preliminary_fit and tip.shape[0] >= MIN_POINTS_KNOWN_RADIUS:
        # the centre these contacts touched (the nominal one can be millimetres off: a
        # joint's error moves every contact alike); the radius is known
        rho = float(reference_sphere(dataset).radius) + float(stylus_radius(dataset) or 0.0)
        try:
            frames["sphere"] = fit_sphere(tip, rho, centre_guess=frames["sphere"]).centre
        except SphereFitError:
            pass
    J = point_jacobian(screws(chain, poses), tip)[:, :, : chain.n]
    velocity = np.einsum("nij,nj->ni", J, directions)
    velocity /= np.maximum(np.linalg.norm(velocity, axis=1, keepdims=True), 1e-300)
    normal = tip - frames["sphere"][None, :]
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    cosine = -np.sum(velocity * normal, axis=1)
    speed: np.ndarray = np.asarray(tip_speed, float) * cosine
    return speed


def robot_chain_of(dataset: Dataset) -> Chain:
    """The nominal chain of a dataset's robot."""
    from hostpc.model.problem import robot_chain

    return robot_chain(dataset)


def with_initial_estimate(dataset: Dataset) -> tuple[Dataset, InitialEstimate]:
    """The dataset with its unknown frames (tool, sphere) replaced by the closed-form
    initial estimate from its contacts (joints as latched, nominal model)."""
    if dataset.method != METHOD:
        raise InputError(f"expected a {METHOD} dataset, got {dataset.method!r}")
    chain = robot_chain_of(dataset)
    T = forward(chain, np.asarray(dataset.samples.q, float)).T_base_flange
    sphere = reference_sphere(dataset)
    tool = dataset.pose("tool")
    rho = float(sphere.radius) + float(stylus_radius(dataset) or 0.0)
    guess = initial_estimate(
        T, np.asarray(dataset.samples.group), rho,
        known_sphere_centre=np.asarray(sphere.center) if "sphere" in dataset.known else None,
        known_tip=np.asarray(tool.xyz) if "tool" in dataset.known else None)
    frames = dict(dataset.frames)
    if "tool" not in dataset.known:
        frames["tool"] = FramePose(xyz=guess.tip, rpy=np.asarray(tool.rpy))
    if "sphere" not in dataset.known:
        frames["sphere"] = SphereFrame(guess.sphere_centre, sphere.radius)
    return replace(dataset, frames=frames), guess


def solve(dataset: Dataset, effects: str | Iterable[str] | None = None, *,
          estimate: bool = True, **options: Any) -> FitResult:
    """The joint solve (S11-S13): start from the initial estimate (if ``estimate``), then
    ``hostpc.fit`` with the given effects (default joint_offsets + unknown frames)."""
    if estimate:
        dataset, _ = with_initial_estimate(dataset)
    return fit(dataset, effects, **options)


def frames_from_result(result: FitResult) -> dict[str, np.ndarray]:
    """Fitted P_b (``sphere``, base, m) and P_t (``tool``, flange, m)."""
    dataset = result.problem.dataset
    out = {"sphere": np.asarray(reference_sphere(dataset).center, float).copy(),
           "tool": np.asarray(dataset.pose("tool").xyz, float).copy()}
    for name in ("sphere", "tool"):
        if name in result.problem.layout.effect_slices:
            out[name] = out[name] + result.effect_values(name)
    return out
