"""The plan of a calibration run: candidate pool, informative fit poses in travel order,
verification poses (none of them a fit pose), and the identifiability check BEFORE anything
moves. Pure numerics apart from the progress messages.

With a target sigma (stereo_target's default) the fit poses are the fewest that reach it
(at least MIN_TARGET_POSES, which stereo_target's centre refinement needs; the selection is
travel-aware, TRAVEL_SLACK; a method whose `ShortPlan` shortens its selection,
stereo_target, swaps them for nearer ones that keep the sigma:
`hostpc.planning.design.shorten_tour`) and CHECK_POSES more, chosen against that fit, that
let the fit's own chi-square see a missing joint compliance, visited as a tour (which a
method whose `ShortPlan` shortens the tour,
world_point, has shortened: `hostpc.planning.design.shorten_tour`; its floor then counts
the shortened plan's poses when fewer); the verification poses are chosen after them
for the most signal against that missing effect per second of robot time
(`hostpc.planning.verify_poses.PowerDesign`), random where the model has it: the
short-robot-time plan. The rest of the selection (up to --poses) is kept as `q_more`, a
tour from the last fit pose, which the runner measures only if the fit does not explain
the measurements. Without one (`--poses N` alone) N poses nearest-neighbour ordered and a
plain random verification choice. A method that plans
whole groups (sphere_probe's probe orientations) takes, with a target sigma (its default),
the fewest leading groups of the nested group selection that reach it as a tour of groups,
the rest as `q_more`, and a random choice of fresh whole groups for verification, toured;
its floor counts those groups' poses and their measuring moves (the guarded approaches).

A plan that can grow has its own path for it: `q_more` then `q_verify_grown` (every
verification pose, toured and unwrapped after the further poses), and its own predicted
robot time (GROWN_TIME). With a cell reference (`--reference`) the reference's frames are
priors in the design, so the joints they resolve count toward the target sigma too
(`hostpc.planning.design.Design.prior`)."""

from __future__ import annotations

import math
from collections.abc import Collection

import numpy as np

from hostpc.calibrate.reference import CellReference
from hostpc.calibrate.run_reference import reference_priors
from hostpc.calibrate.run_result import GROWN_TIME
from hostpc.diagnostics.detectable import planned_sizes
from hostpc.diagnostics.pipeline import DEFAULT_ALPHA
from hostpc.errors import InputError
from hostpc.fitting.priors import constraints_for, with_constraints
from hostpc.json_object import JsonObject
from hostpc.methods import method_class
from hostpc.methods.base import Method, Plan, Progress, RunSettings
from hostpc.planning.design import (
    Design,
    Travel,
    check_plan,
    design_matrix,
    group_selection,
    groups_for_target_sigma,
    in_pool_order,
    joint_offset_sigmas,
    make_design,
    order_for_travel,
    poses_for_target_sigma,
    prior_bounded_joints,
    select,
    shorten_tour,
    tour_groups,
    verify_groups,
)
from hostpc.planning.robot_time import (
    RobotPath,
    TimeLimits,
    Waypoints,
    path_floor,
    predicted_robot_time,
    robot_time_floor,
)
from hostpc.planning.tour import Rates, full_turn_joints, short_path, unwrap_plan
from hostpc.planning.verify_poses import POWER_EFFECTS, PowerDesign, nearby_verify_poses
from hostpc.robots.base import RobotState

EXTENDED_VERIFY_POSES = 12
"""Verification poses of a short plan that had to grow (its model failed the fit): 4
nearby-in-time poses lack the power against the unmodelled effect (docs/performance.md: 15
of 20 forced pushes caught with 4, 20 of 20 with 10); 12, not a fixed plan's 10: after a
60-pose fit of the lean model the hidden compliance world's seed 214 passed 10 poses at p =
0.054 and FAILs 12 at p = 0.0005. Only a run whose model failed pays for them. A method
that plans whole groups takes whole groups up to at least this count (sphere_probe: 3
orientations of 5 contacts, 15)."""


FLOOR_SIGMA_DEG = 0.002
"""The joint-offset sigma (deg) of a plan's robot-time floor when the run sets no
--target-sigma: the floor is the settle and capture of the fewest selected poses that
reach it, plus the verification poses (`hostpc.planning.robot_time`)."""


class PlanningError(InputError):
    """The planned poses cannot separate the model's parameters (or none are reachable)."""


MIN_TARGET_POSES = 6
"""A target-sigma plan measures at least this many poses: the fewest whose disk centres
stereo_target re-corrects with the normals of their own preliminary fit
(`hostpc.kinds.stereo_target.refinement.MIN_SAMPLES`; a test keeps the two equal). The sigma
target itself asks for 7-8 poses (10-11 with the travel-aware selection). This was 20 while
a plan of fewer than 20 poses went unrefined, which, not the plan's size, made its sigma
dishonest: refined, the plain 7-8-pose plan gives MSE / sigma^2 0.68-1.32 per joint over 40
simulated worlds (1.29 0.69 2.09 1.50 2.11 unrefined; `bench/bench_sigma_mc.py --worlds 40
--methods stereo_target`, docs/performance.md "Default plan size and the honesty of its
sigma")."""


TRAVEL_SLACK = 0.15
"""A short plan's selection is travel-aware (`hostpc.planning.design.Travel`): each step
takes, of the poses whose information gain (the ridged log det, `design.Travel`'s caveat)
is within 15 % of the best, the one nearest the poses already chosen. Chosen on simulated
worlds 1-40 (`bench/bench_sigma_mc.py`; robot time from their result.json): 0 (plain
D-optimal) gave 7 poses, 18.6 s of robot time on average, MSE / sigma^2 0.70-1.26; 0.15
gives 10-11 poses in 17.8 s (at most 19.8 s), 0.96-1.18; 0.3 gives 15 poses in 18.1 s (2 of
40 runs above 20 s) and sigmas too large (q1 0.51). More poses in the same time: shorter
moves between them."""


def plan_warnings(method: str | type[Method], target_sigma_deg: float | None,
                  sigmas: np.ndarray, n_fit: int, short: bool,
                  by_reference: Collection[int] = ()) -> list[str]:
    """What a plan does not deliver, one line each: a target sigma the planned poses do not
    reach (sigmas: (n,) predicted joint-offset sigmas, rad, NaN where not identifiable;
    by_reference: the joints only a cell reference's frames identify, whose sigma those
    frames bound: said apart, more poses do not help), and what a short plan lacks for its
    method (``Method.short_plan_warning``: stereo_target's below the centre refinement's
    MIN_TARGET_POSES, whose centres then keep the nominal normal's bias, docs/vision.md
    3.2). method: the Method class, or a built-in's name."""
    lines: list[str] = []
    sigmas = np.asarray(sigmas, float).copy()
    for j in sorted(by_reference):
        lines.append(f"plan: joint {j + 1} reaches a predicted sigma of "
                     f"{math.degrees(float(sigmas[j])):.2g} deg: only the cell reference's "
                     "frames identify it, and their uncertainty bounds it (more poses do not "
                     "lower it)")
        sigmas[j] = np.nan
    finite = np.isfinite(sigmas)
    if target_sigma_deg is not None and np.any(finite):
        worst = int(np.argmax(np.where(finite, sigmas, -np.inf)))
        if math.degrees(float(sigmas[worst])) > target_sigma_deg:
            lines.append(f"plan: the {n_fit} poses reach a predicted sigma of "
                         f"{math.degrees(float(sigmas[worst])):.2g} deg (joint {worst + 1}), "
                         f"not the --target-sigma {target_sigma_deg:g} deg: give more --poses")
    cls = method_class(method) if isinstance(method, str) else method
    warning = cls.short_plan_warning(n_fit) if short else None
    if warning is not None:
        lines.append(warning)
    return lines


CHECK_POSES = 2
"""Fit poses a short plan adds to the fewest that reach the target sigma so that the fit's
own chi-square sees a missing joint compliance (`PowerDesign.check_poses`): the poses
that reach the sigma at least travel are compact, a compact fit absorbs the bending into
its offsets, and the plan would not grow when the model fails (the hidden-compliance
walk-through of README and docs/diagnostics.md; tests/integration/test_diagnose_from_stub.py
failed without them once the plan was planned with the rig's measured pixel noise: 6-7
poses). Two check poses raise the fit's non-centrality against that bending 2-4x more
than two more selected poses (tests/hostpc/test_verify_power.py)."""


def power_design(method: Method, design: Design, pool: np.ndarray, settings: RunSettings
                 ) -> PowerDesign | None:
    """Where the pool's poses see the effects the model lacks (verify_poses.POWER_EFFECTS):
    for the check poses and the verification poses of a short plan; None when the model
    has them all or the method's measurements cannot carry them."""
    base = list(dict.fromkeys(name.split(".", 1)[0] for name in design.names))
    missing = [e for e in POWER_EFFECTS if e not in base]
    if not missing:
        return None
    try:
        A, names, _ = design_matrix(method.design_dataset(pool), base + missing,
                                    settings.plugins, pool.shape[0])
    except InputError:  # an effect the method's measurements cannot carry
        return None
    if not set(design.names) <= set(names):
        return None
    own = [names.index(n) for n in design.names]
    extra = [k for k, n in enumerate(names) if n not in design.names]
    return PowerDesign.scaled(A[:, :, own], A[:, :, extra])


def grown_path(pool: np.ndarray, more: np.ndarray, q_more: np.ndarray,
               verify: np.ndarray, q_from: np.ndarray, limits: tuple[np.ndarray, np.ndarray],
               rates: Rates = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The path a short plan takes once it grew, from its last fit pose q_from (n,): the
    further fit poses (`more`, pool indices, visited as q_more (M, n)), then every
    verification pose of the grown plan (`verify`, pool indices) as a tour from the last
    of them, the whole unwrapped as one path (`tour.unwrap_plan`): the verification poses'
    angles of the short path are the equivalents nearest the fit tour's end, and from
    q_more's end one of them can be more than half a turn away (a wrist unwinding).
    Returns (q_more, the verification poses, more), each in the grown path's order;
    rates: the moves' speeds and accelerations (`tour.move_times`)."""
    order, _ = short_path(pool[verify], q_more[-1], *limits, rates)
    orders, (q_more, q_verify) = unwrap_plan([q_more, pool[verify[order]]], q_from, *limits,
                                             rates)
    return q_more, q_verify, more[orders[0]]


def plan_run(method: Method, state: RobotState, settings: RunSettings, progress: Progress,
             reference: CellReference | None = None) -> Plan:
    """Candidate pool, informative selection, order, verification poses, check; with a
    cell reference its frames' priors are part of every plan's information (the target
    sigma then holds for the joints they resolve, `hostpc.planning.design.Design.prior`)."""
    progress.stage("plan")
    rng = np.random.default_rng(settings.seed)
    pool = method.candidates(state, rng)
    needed = settings.n_poses + settings.n_verify
    if pool.shape[0] < max(needed, 1):
        raise PlanningError(
            f"only {pool.shape[0]} reachable poses see the target (need {needed}); check "
            "the cell (target position, camera mount) and the joint limits")
    # the run's --hold and --prior are part of the design: a held joint gets no sigma
    dataset = with_constraints(method.design_dataset(pool), settings.priors, settings.hold)
    try:  # a --reference's frames: the joints they resolve get the target sigma too
        dataset = reference_priors(reference, dataset, settings)[0]
    except (InputError, ValueError, np.linalg.LinAlgError):
        pass  # unusable here (e.g. another rig's camera frame): with_joint_coverage says why
    A, names, units = design_matrix(dataset, settings.effects, settings.plugins,
                                    pool.shape[0])
    constraints = constraints_for(dataset.extra_fields, names, units)
    design = make_design(A, names, units, None if constraints is None or not
                         constraints.index.size else constraints.jacobian(len(names)),
                         None if constraints is None else constraints.held)
    structural = design.structural
    groups = method.pose_groups(pool)
    more = np.zeros(0, dtype=int)
    short = groups is None and settings.target_sigma_deg is not None  # short robot time
    limits = (state.q_min, state.q_max)
    time_limits = TimeLimits.from_extra(state.extra, state.q.size)
    rates = time_limits.rates(settings.speed)  # every move's time (tour.move_times)
    q_more: np.ndarray | None = None
    reaching: int | None = None  # the poses of a shortened plan (they reach the target)
    per_pose_s = time_limits.settle_s + time_limits.capture_s
    if groups is None:
        travel = None
        if short:  # prefer informative poses near the ones already chosen
            travel = (Travel(pool, np.asarray(state.q, float), full_turn_joints(*limits),
                             rates=rates,
                             per_pose_s=per_pose_s)
                      if method.short_plan.selection == "per_second" else
                      Travel(pool, np.asarray(state.q, float), full_turn_joints(*limits),
                             TRAVEL_SLACK))
        chosen = select(design, settings.n_poses, settings.criterion, rng, travel)
        selection = chosen
        if settings.target_sigma_deg is not None:  # the fewest poses that reach it
            enough = poses_for_target_sigma(design, chosen,
                                            math.radians(settings.target_sigma_deg),
                                            state.q.size, min_poses=MIN_TARGET_POSES)
            more = np.zeros(0, dtype=int) if enough is None else chosen[enough:]
            chosen = chosen if enough is None else chosen[:enough]

        def shortened(tour: np.ndarray, fixed: np.ndarray, min_poses: int) -> np.ndarray:
            return shorten_tour(
                design, pool, tour, state.q,
                math.radians(settings.target_sigma_deg or FLOOR_SIGMA_DEG), state.q.size,
                per_pose_s, rates, full_turn_joints(*limits), fixed, min_poses)

        if short and method.short_plan.shorten == "selection" and enough is not None:
            # nearer poses that keep the target sigma, before the check poses are chosen
            # against the fit the run measures
            chosen = shortened(chosen[short_path(pool[chosen], state.q, *limits, rates)[0]],
                               np.zeros(0, dtype=int), MIN_TARGET_POSES)
            more = more[~np.isin(more, chosen)]
            reaching = chosen.size
        power = power_design(method, design, pool, settings) if short else None
        # fit poses that see a missing effect, within --poses (the most the plan measures)
        n_check = min(CHECK_POSES, max(0, settings.n_poses - chosen.size))
        check_poses = np.zeros(0, dtype=int)
        if power is not None and n_check > 0:
            unused = np.setdiff1d(np.arange(pool.shape[0]), chosen)
            check_poses = power.check_poses(chosen, unused, n_check, pool, rates, per_pose_s)
            chosen = np.concatenate([chosen, check_poses])
            more = more[~np.isin(more, check_poses)][:max(0, settings.n_poses - chosen.size)]
        if short:  # a tour, full-turn joints the short way round (tour.short_path)
            order, q_short = short_path(pool[chosen], state.q, *limits, rates)
            fit_indices = chosen[order]
            if method.short_plan.shorten == "tour" and enough is not None:  # fewer, nearer
                fit_indices = shortened(fit_indices, check_poses, 0)
                order, q_short = short_path(pool[fit_indices], state.q, *limits, rates)
                fit_indices = fit_indices[order]
                reaching = fit_indices.size
                more = more[~np.isin(more, fit_indices)]
        else:
            fit_indices = chosen[order_for_travel(pool[chosen], state.q, rates)]
        if more.size:  # measured only if the model fails (runner): a tour from the last
            order, q_more = short_path(pool[more], q_short[-1], *limits, rates)
            more = more[order]
    else:  # whole groups (sphere_probe: an orientation's 5 contacts)
        ordered = group_selection(design, groups, settings.n_poses, settings.criterion, rng)
        enough = groups_for_target_sigma(
            design, ordered, math.radians(settings.target_sigma_deg or FLOOR_SIGMA_DEG),
            state.q.size, groups.min_groups)
        floor_groups = ordered[:enough or len(ordered)]
        if settings.target_sigma_deg is not None and enough is not None:
            # the fewest groups that reach it as a tour; the rest if the model fails
            fit_indices = tour_groups(pool, groups, np.concatenate(ordered[:enough]), state.q,
                                      rates)
            if enough < len(ordered):
                more = tour_groups(pool, groups, np.concatenate(ordered[enough:]),
                                   pool[fit_indices[-1]], rates)
                q_more = pool[more]
        else:  # in the pool order (the method's safe visiting order)
            fit_indices = in_pool_order(ordered)
        selection = fit_indices
    plan_design = design.subset(fit_indices)
    check = check_plan(plan_design)
    if not check.ok:
        lines = "; ".join(d.description for d in check.deficient)
        raise PlanningError(
            f"the {len(fit_indices)} planned poses cannot separate the model's parameters "
            f"(rank {check.plan_rank} of {check.pool_rank}): {lines}. Fix: more poses "
            "(--poses), fewer effects (--effects), or a wider pose range")
    q_fit = q_short if short else pool[fit_indices]
    last = q_fit[-1] if q_fit.shape[0] else state.q
    q_verify_grown: np.ndarray | None = None
    if short:
        rest = np.setdiff1d(np.arange(pool.shape[0]), np.concatenate([fit_indices, more]))
        if power is not None and settings.n_verify > 0:  # most signal per second
            verify_indices = power.choose(
                fit_indices, rest, settings.n_verify, pool, last, rates,
                time_limits.settle_s + time_limits.capture_s, limits)
        else:  # a random choice, toured
            verify_indices = nearby_verify_poses(pool, rest, last, settings.n_verify, rng)
        order, q_verify = short_path(pool[verify_indices], last, *limits, rates)
        verify_indices = verify_indices[order]
        # the whole plan as one path: a joint wound up by the fit tour must not unwind on
        # the way to the verification poses (tour.unwrap_plan)
        orders, (q_fit, q_verify) = unwrap_plan([q_fit, q_verify], state.q, *limits, rates)
        fit_indices, verify_indices = fit_indices[orders[0]], verify_indices[orders[1]]
        if q_more is not None:  # if the model fails: q_more, then EXTENDED_VERIFY_POSES
            rest = np.setdiff1d(rest, verify_indices)
            from_pose = q_verify[-1] if verify_indices.size else last
            extra = nearby_verify_poses(
                pool, rest, from_pose, max(0, EXTENDED_VERIFY_POSES - verify_indices.size),
                rng)
            q_more, q_verify_grown, more = grown_path(pool, more, q_more, np.concatenate(
                [verify_indices, extra]), q_fit[-1], limits, rates)
    elif groups is None:
        rest = np.setdiff1d(np.arange(pool.shape[0]), fit_indices)
        verify_indices = rng.choice(rest, size=min(settings.n_verify, rest.size),
                                    replace=False)
        verify_indices = verify_indices[order_for_travel(pool[verify_indices], last, rates)]
    else:
        used = np.concatenate([fit_indices, more])
        verify_indices = verify_groups(groups, used, settings.n_verify, rng)
        if settings.target_sigma_deg is not None:
            verify_indices = tour_groups(pool, groups, verify_indices, last, rates)
        if more.size:  # a grown plan verifies with EXTENDED_VERIFY_POSES, whole groups
            extra = verify_groups(groups, np.concatenate([used, verify_indices]),
                                  EXTENDED_VERIFY_POSES - verify_indices.size, rng)
            from_pose = pool[verify_indices[-1]] if verify_indices.size else last
            q_verify_grown = pool[np.concatenate(
                [verify_indices, tour_groups(pool, groups, extra, from_pose, rates)])]
    if not short:
        q_verify = pool[verify_indices]
    if not short and groups is None:  # full-turn joints: no unwinding (tour.unwrap_plan)
        orders, (q_fit, q_verify) = unwrap_plan([q_fit, q_verify], state.q, *limits, rates)
        fit_indices, verify_indices = fit_indices[orders[0]], verify_indices[orders[1]]
    sigmas = joint_offset_sigmas(plan_design, state.q.size)
    bounded = ({} if settings.target_sigma_deg is None else prior_bounded_joints(
        design, fit_indices, math.radians(settings.target_sigma_deg), state.q.size))
    for line in plan_warnings(type(method), settings.target_sigma_deg, sigmas,
                              len(fit_indices), short, bounded):
        progress.message(line)
    info: JsonObject = {
        "criterion": settings.criterion,
        "target_sigma_deg": settings.target_sigma_deg,
        "n_candidates": int(pool.shape[0]),
        "parameters": list(names),
        "predicted_joint_sigma_deg": [None if not np.isfinite(s) else math.degrees(s)
                                      for s in sigmas],
        "structural_unidentifiable": [d.description for d in structural],
        "structural_fixed": [d.fixed for d in structural],
    }
    path = method.robot_path if isinstance(method, RobotPath) else Waypoints.plain
    if groups is None:
        fewest = poses_for_target_sigma(
            design, selection, math.radians(settings.target_sigma_deg or FLOOR_SIGMA_DEG),
            state.q.size)
        if reaching is not None and fewest is not None:  # a shortened plan: fewer reach it
            fewest = min(fewest, reaching)
        n_fewest = fewest or len(selection)

        def floor(verify: np.ndarray) -> float:
            return robot_time_floor(n_fewest + verify.shape[0], time_limits)
    else:  # the fewest whole groups, with their measuring moves (guarded approaches)
        fewest_q = pool[np.concatenate(floor_groups)]

        def floor(verify: np.ndarray) -> float:
            return path_floor(path(np.vstack([fewest_q, verify])), settings.speed, time_limits)
    planned = predicted_robot_time(state.q, path(q_fit), path(q_verify), settings.speed,
                                   time_limits, floor(q_verify))
    info["predicted_robot_time_s"] = planned
    if q_more is not None and q_verify_grown is not None:  # the plan if its model fails
        info[GROWN_TIME] = predicted_robot_time(
            state.q, path(np.vstack([q_fit, q_more])), path(q_verify_grown), settings.speed,
            time_limits, floor(q_verify_grown))
    progress.message(
        f"plan: {len(fit_indices)} poses from {pool.shape[0]} candidates "
        f"({settings.criterion}-optimal), {q_verify.shape[0]} verification poses; "
        "predicted joint offset sigma "
        + ", ".join("-" if not np.isfinite(s) else f"{math.degrees(s):.4f}"
                    for s in sigmas) + " deg; predicted robot time of measure + verify "
        f"{planned['total']:.1f} s (motion {planned['motion']:.1f}, settle "
        f"{planned['settle']:.1f}, capture {planned['capture']:.1f}; floor "
        f"{planned['floor']:.1f})")
    detectable = planned_sizes(method.design_dataset(q_fit), settings.effects,
                               settings.plugins, DEFAULT_ALPHA)
    info["detectable"] = [d.to_dict() for d in detectable]
    if detectable:
        progress.message("plan: smallest effects these poses would find (80 % power, "
                         "before measuring): " + "; ".join(d.short for d in detectable))
    if more.size:
        info["more_poses"] = int(more.size)
    return Plan(q=q_fit, q_verify=q_verify, info=info, q_more=q_more,
                q_verify_grown=q_verify_grown)
