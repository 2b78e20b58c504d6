"""Tours: the visiting order of planned poses that shortens the robot's travel time.

Pure numerics (no robot, no I/O). A joint move to the next pose is synchronized along the
straight joint-space line, every joint ramping up to its speed and down to rest (a
trapezoidal velocity profile; `move_times`, the one motion-time law of the host):

    tau_v = max_i |dq_i| / v_i      (the move at top speed from the first instant)
    tau_a = max_i |dq_i| / a_i      (s^2)
    t(a, b) = 2 sqrt(tau_a)                  if tau_v^2 <= tau_a (too short to reach speed)
              tau_v + tau_a / tau_v          otherwise

(v_i the joint's speed at the run's speed fraction, rad/s; a_i its acceleration, rad/s^2).
The path parameter's speed and acceleration are the tightest of the joints' v_i / |dq_i|
and a_i / |dq_i|, so no joint exceeds its own; with equal limits on every joint this is
the slowest joint's d / v + v / a (or 2 sqrt(d / a) for a triangular profile). The
simulator moves by the same law (`controller_stub.world.motion.PathProfile`, its own
copy). Without accelerations (`joint_speed` a plain array: a_i infinite) a move takes
tau_v, without speeds (None: v_i = 1) the largest joint motion (rad: only ratios matter).

A tour is an open path that starts at the robot's current pose and visits every planned
pose once; its cost is the sum of the moves' times (symmetric: a move back takes as long).
The travelling-salesman problem behind it is hard, and a good tour is enough:

1. start from the shorter of the nearest-neighbour path and the given (selection) order;
2. improve it by 2-opt (reverse the segment between two moves when that shortens the path,
   the first pose stays attached to the start) until no reversal helps.

So a tour is never longer than the selection order nor than nearest neighbour. The cost
is symmetric, so reversing a segment leaves its inner moves unchanged and a reversal's gain
is computed from the two moves it replaces.

Joints that turn more than a full turn (a UR's +-360 deg) reach a pose by any angle
q + 2 pi m within their limits: with `periodic` (n,) bool such a joint's move is the shorter
way round, min(|dq|, 2 pi - |dq|), and `unwrap_path` then picks, pose after pose, the
equivalent angle nearest the previous one (within the limits), so the robot really moves
the short way. The kinematics is 2 pi periodic, so the measurement does not change.

Shapes: q (N, n) rad; q_start (n,) rad; joint_speed: `JointRates` ((n,) rad/s and
rad/s^2), or (n,) rad/s (no ramp), or None (all equal, no ramp); periodic (n,) bool (or
None: no joint).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

MAX_PASSES = 50
UNWIND_PENALTY = 10.0
"""`unwrap_path` charges a full-turn joint's move beyond half a turn this many times its
excess: it avoids unwinding moves (a UR's wrist 3 turning 228-298 deg between two poses
against its +-360 deg limit) wherever an equivalent angle allows it."""


@dataclass(frozen=True)
class JointRates:
    """A move's joint limits: speed (n,) rad/s (the top speeds x the move's speed
    fraction), acceleration (n,) rad/s^2 (each broadcasts against the moves: (..., n))."""

    speed: np.ndarray
    acceleration: np.ndarray


Rates = JointRates | np.ndarray | None
"""What the tour functions time moves with (the module docstring)."""


def move_times(q_from: np.ndarray, q_to: np.ndarray, joint_speed: Rates = None,
               periodic: np.ndarray | None = None) -> np.ndarray:
    """Times (s) of joint moves q_from[k] -> q_to[k] ((..., n) each, broadcast) by the
    module's law (speeds alone: no ramp, tau_v; joint_speed None: the largest joint motion,
    rad); a periodic joint's |dq| the shorter way round."""
    dq = np.abs(np.asarray(q_to, float) - np.asarray(q_from, float))
    if periodic is not None and np.any(periodic):
        around = np.mod(dq, 2 * np.pi)
        dq = np.where(periodic, np.minimum(around, 2 * np.pi - around), dq)
    rates = (joint_speed if isinstance(joint_speed, JointRates)
             else JointRates(np.asarray(1.0 if joint_speed is None else joint_speed, float),
                             np.asarray(np.inf)))
    tau_v = np.max(dq / np.asarray(rates.speed, float), axis=-1)
    tau_a = np.max(dq / np.asarray(rates.acceleration, float), axis=-1)
    triangular = tau_v * tau_v <= tau_a
    cruising = tau_v + tau_a / np.where(triangular, 1.0, tau_v)
    return np.asarray(np.where(triangular, 2.0 * np.sqrt(tau_a), cruising))


def nearest_equivalents(q_from: np.ndarray, q: np.ndarray, q_min: np.ndarray,
                        q_max: np.ndarray) -> np.ndarray:
    """q (N, n) with each full-turn joint's angle replaced by its equivalent q + 2 pi m
    nearest q_from (n,) within [q_min, q_max] (as it is where none is within): the angles
    a move from q_from really reaches, so its time is that of a move that never unwinds."""
    q = np.asarray(q, float).copy()
    joints = np.flatnonzero(full_turn_joints(q_min, q_max))
    if joints.size == 0 or q.shape[0] == 0:
        return q
    options = q[:, joints, None] + 2 * np.pi * np.arange(-2, 3)[None, None, :]
    lo = np.asarray(q_min, float)[joints, None]
    hi = np.asarray(q_max, float)[joints, None]
    distance = np.abs(options - np.asarray(q_from, float)[joints, None])
    distance = np.where((options >= lo) & (options <= hi), distance, np.inf)
    best = np.argmin(distance, axis=2)
    within = np.isfinite(np.min(distance, axis=2))
    chosen = np.take_along_axis(options, best[:, :, None], axis=2)[:, :, 0]
    q[:, joints] = np.where(within, chosen, q[:, joints])
    return q


def path_time(q: np.ndarray, q_start: np.ndarray | None = None,
              joint_speed: Rates = None,
              periodic: np.ndarray | None = None) -> float:
    """Travel time (s; rad with equal speeds) of visiting q (N, n) in its order from
    q_start (none: from the first pose)."""
    q = np.asarray(q, float)
    if q.shape[0] == 0:
        return 0.0
    path = q if q_start is None else np.vstack([np.asarray(q_start, float)[None, :], q])
    return float(np.sum(move_times(path[:-1], path[1:], joint_speed, periodic)))


def nearest_neighbour(q: np.ndarray, q_start: np.ndarray | None,
                      joint_speed: Rates = None,
                      periodic: np.ndarray | None = None) -> np.ndarray:
    """Indices into q (N, n): always move to the nearest unvisited pose, from q_start (or
    from the first pose)."""
    n_poses = q.shape[0]
    if n_poses == 0:
        return np.zeros(0, dtype=int)
    remaining = list(range(n_poses))
    current = q_start if q_start is not None else q[0]
    order: list[int] = []
    while remaining:
        cost = move_times(current, q[remaining], joint_speed, periodic)
        k = remaining.pop(int(np.argmin(cost)))
        order.append(k)
        current = q[k]
    return np.asarray(order, dtype=int)


def two_opt(q: np.ndarray, order: np.ndarray, q_start: np.ndarray | None,
            joint_speed: Rates = None,
            periodic: np.ndarray | None = None) -> np.ndarray:
    """`order` (indices into q) improved by 2-opt segment reversals until none shortens
    the open path from q_start (with q_start None the first pose of `order` stays first)."""
    order = np.asarray(order, dtype=int).copy()
    if order.size < 3 and q_start is None:
        return order
    head = np.asarray(q_start if q_start is not None else q[order[0]], float)
    body = order if q_start is not None else order[1:]
    fixed = 0 if q_start is not None else 1
    nodes = np.vstack([head[None, :], q[body]])  # node 0 is the fixed start
    D = move_times(nodes[:, None, :], nodes[None, :, :], joint_speed, periodic)
    path = np.arange(nodes.shape[0])
    m = path.size
    for _ in range(MAX_PASSES):
        improved = False
        for i in range(1, m - 1):
            # reverse path[i..j]: moves (i-1 -> i) and (j -> j+1) become (i-1 -> j), (i -> j+1)
            a, b = path[i - 1], path[i]
            c = path[i + 1:]
            removed = D[a, b] + np.append(D[c[:-1], c[1:]], 0.0)
            added = D[a, c] + np.append(D[b, c[1:]], 0.0)
            gain = removed - added
            k = int(np.argmax(gain))
            if gain[k] > 1e-12 * max(float(removed[k]), 1e-12):
                j = i + 1 + k
                path[i:j + 1] = path[i:j + 1][::-1].copy()
                improved = True
        if not improved:
            break
    tour = body[path[1:] - 1]
    return tour if fixed == 0 else np.concatenate([order[:1], tour])


def plan_tour(q: np.ndarray, q_start: np.ndarray | None,
              joint_speed: Rates = None,
              periodic: np.ndarray | None = None) -> np.ndarray:
    """Visiting order (indices into q (N, n)) of a short tour from q_start (see the module
    docstring): never longer than the given order nor than nearest neighbour."""
    q = np.asarray(q, float)
    n_poses = q.shape[0]
    if n_poses == 0:
        return np.zeros(0, dtype=int)
    given = np.arange(n_poses)
    greedy = nearest_neighbour(q, q_start, joint_speed, periodic)
    start = min((given, greedy),
                key=lambda o: path_time(q[o], q_start, joint_speed, periodic))
    return two_opt(q, start, q_start, joint_speed, periodic)


def full_turn_joints(q_min: np.ndarray, q_max: np.ndarray) -> np.ndarray:
    """(n,) bool: the joints whose limits span at least a full turn (2 pi)."""
    return np.asarray(q_max, float) - np.asarray(q_min, float) >= 2 * np.pi


def unwrap_path(q: np.ndarray, q_start: np.ndarray, q_min: np.ndarray, q_max: np.ndarray
                ) -> np.ndarray:
    """q (N, n) in visiting order with each full-turn joint's angle replaced by an
    equivalent q + 2 pi m within [q_min, q_max]: per joint, the choice that minimises the
    joint's total travel from q_start (dynamic programming over the 5 equivalents of each
    pose), a move of more than half a turn charged UNWIND_PENALTY times its excess, so a
    joint does not wind itself into its limit and then unwind. Unwrap a whole plan (fit and
    verification poses) in one call: a tour unwrapped alone can end wound up so far that
    the next tour must unwind. The same poses."""
    q = np.asarray(q, float)
    return _unwrap_paths(q, np.arange(q.shape[0])[None], q_start, q_min, q_max)[0]


def _unwrap_paths(poses: np.ndarray, visits: np.ndarray, q_start: np.ndarray,
                  q_min: np.ndarray, q_max: np.ndarray) -> np.ndarray:
    """`unwrap_path` of T paths at once, path t visiting poses[visits[t]] (poses (P, n),
    visits (T, N) indices): (T, N, n). One dynamic programme over every path and full-turn
    joint, each move's costs computed once per pair of poses: the same arithmetic on each
    element as one path alone, so the same choices."""
    out = poses[visits]
    n_paths, n_poses = visits.shape
    joints = np.flatnonzero(full_turn_joints(q_min, q_max))
    if n_poses == 0 or joints.size == 0:
        return out
    # options[p, j, b]: pose p's joint j as its equivalent b (5 of them)
    shifts = 2 * np.pi * np.arange(-2, 3)
    options = poses[:, joints, None] + shifts
    lo, hi = np.asarray(q_min, float)[joints, None], np.asarray(q_max, float)[joints, None]
    allowed = (options >= lo) & (options <= hi)
    none = ~allowed.any(axis=2)
    allowed[:, :, 2] |= none  # none within the limits: keep it as it is
    # only the equivalents some pose may take (a UR's +-360 deg: q - 2 pi, q, q + 2 pi): one
    # never allowed costs inf at every step, so it is never the cheapest (every joint has an
    # allowed one) and dropping it changes no choice
    keep = np.flatnonzero(allowed.any(axis=(0, 1)))
    options, allowed = options[:, :, keep], allowed[:, :, keep]
    barrier = np.where(allowed, 0.0, np.inf)  # added: cost + 0 is the cost, + inf is inf
    start = np.asarray(q_start, float)[joints, None]
    first = visits[:, 0]
    cost = _joint_cost(options[first] - start) + barrier[first]  # (T, J, options)
    # moves[m, j, a, b]: cost of reaching option b of a pose from option a of the one before,
    # for each pair m of consecutive poses of the paths (pair[t, k - 1])
    if n_paths == 1:
        before, after, pair = visits[0, :-1], visits[0, 1:], np.arange(n_poses - 1)[None]
    else:  # the pairs the paths share once
        keys = visits[:, :-1] * poses.shape[0] + visits[:, 1:]
        used = np.zeros(poses.shape[0] ** 2, dtype=bool)
        used[keys] = True
        before, after = np.divmod(np.flatnonzero(used), poses.shape[0])
        pair = (np.cumsum(used) - 1)[keys]
    moves = _joint_cost(options[after][:, :, None, :] - options[before][:, :, :, None])
    choice = np.zeros((n_poses, n_paths, joints.size, keep.size), dtype=np.int8)
    for k in range(1, n_poses):
        # the cheapest way into each option: the first that gives the least (argmin)
        step = moves[pair[:, k - 1]]  # (T, J, options, options)
        reached = cost[:, :, 0, None] + step[:, :, 0]
        for option in range(1, keep.size):
            trial = cost[:, :, option, None] + step[:, :, option]
            less = trial < reached
            reached = np.minimum(reached, trial)
            np.putmask(choice[k], less, option)
        cost = reached + barrier[visits[:, k]]
    # back from the cheapest last option, by flat indices into choice[k] and options
    size = keep.size
    cell = np.arange(n_paths * joints.size).reshape(n_paths, joints.size) * size
    joint = np.arange(joints.size) * size
    best = np.argmin(cost, axis=2)  # (T, J)
    for k in range(n_poses - 1, -1, -1):
        out[:, k, joints] = options.take(visits[:, k, None] * (joints.size * size) + joint + best)
        best = choice[k].take(cell + best)
    return out


def _excess(q: np.ndarray, q_start: np.ndarray, q_min: np.ndarray, q_max: np.ndarray
            ) -> np.ndarray:
    """(..., N, k) rad: what each full-turn joint's move to each pose of q (..., N, n), from
    the previous one (q_start for the first), exceeds half a turn by (0 if it does not)."""
    q = np.asarray(q, float)
    start = np.broadcast_to(np.asarray(q_start, float), (*q.shape[:-2], 1, q.shape[-1]))
    path = np.concatenate([start, q], axis=-2)
    size = np.abs(np.diff(path, axis=-2))[..., full_turn_joints(q_min, q_max)]
    return np.maximum(size - np.pi, 0.0)


def unwinding(q: np.ndarray, q_start: np.ndarray, q_min: np.ndarray, q_max: np.ndarray
              ) -> float:
    """What the full-turn joints' moves along q (N, n) from q_start exceed half a turn by,
    summed (rad): 0 for a path on which no joint unwinds."""
    return float(np.sum(_excess(q, q_start, q_min, q_max)))


def unwinding_moves(q: np.ndarray, q_start: np.ndarray, q_min: np.ndarray,
                    q_max: np.ndarray) -> np.ndarray:
    """Indices into q (N, n) of the poses reached by an unwinding move from the previous
    one (from q_start for the first): a full-turn joint moves more than half a turn."""
    return np.flatnonzero(np.any(_excess(q, q_start, q_min, q_max) > 0.0, axis=1))


def unwrap_plan(parts: list[np.ndarray], q_start: np.ndarray, q_min: np.ndarray,
                q_max: np.ndarray, joint_speed: Rates = None
                ) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """The consecutive tours `parts` ((N_k, n) each, visited one after the other from
    q_start) as one path with no joint unwinding where their orders allow it: (orders (N_k,)
    into each part, the parts' poses in that order, unwrapped as one path (`unwrap_path`)).

    Each tour is kept as it is unless the unwrapped whole still unwinds a joint (a tour
    wound up so far that an equivalent angle of the next pose lies beyond the limit); then
    2-opt reversals inside each tour, judged by the unwrapped whole's travel time plus
    UNWIND_PENALTY x the time of a move of its `unwinding`, until none helps: first the
    reversals that replace an unwinding move, then any (a tour that ends wound up less;
    each trial unwraps the whole path). So the IK branch of every full-turn joint is chosen
    over the whole plan, not pose by pose."""
    q_start = np.asarray(q_start, float)
    blocks = [np.asarray(p, float).reshape(-1, q_start.size) for p in parts]
    orders = [np.arange(b.shape[0]) for b in blocks]

    def whole(orders: list[np.ndarray]) -> np.ndarray:
        return unwrap_path(np.vstack([b[o] for b, o in zip(blocks, orders, strict=True)]),
                           q_start, q_min, q_max)

    def costs(paths: np.ndarray) -> np.ndarray:
        # (T,) of T unwrapped paths (T, N, n): `path_time` plus the `unwinding` charged as
        # UNWIND_PENALTY moves of its size (sums along each path's own row: as for one path alone)
        steps = np.concatenate([np.broadcast_to(q_start, (paths.shape[0], 1, q_start.size)),
                                paths], axis=1)
        times = move_times(steps[:, :-1], steps[:, 1:], joint_speed)
        unwound = np.sum(_excess(paths, q_start, q_min, q_max), axis=(1, 2))
        excess = np.repeat(unwound[:, None], q_start.size, axis=1)
        return (np.sum(times, axis=1)
                + UNWIND_PENALTY * move_times(0.0 * excess, excess, joint_speed))

    path = whole(orders)
    best = float(costs(path[None])[0])
    first = np.cumsum([0] + [b.shape[0] for b in blocks])[:-1]  # each part's first pose
    poses = np.vstack(blocks)
    for _ in range(MAX_PASSES):
        moves = unwinding_moves(path, q_start, q_min, q_max)
        spans: list[tuple[int, int, int]] = []  # (part, i, j): reverse orders[part][i..j]
        for m in moves:
            k = int(np.searchsorted(first, m, side="right")) - 1
            local, size = int(m - first[k]), orders[k].size
            # the reversals of part k that end just before the pose the move reaches, or
            # start at it: they replace that move
            spans += [(k, i, local - 1) for i in range(local - 1)]
            spans += [(k, local, j) for j in range(local + 1, size)]
        if moves.size:  # then any reversal: one earlier may wind the joint less
            spans += [(k, i, j) for k, order in enumerate(orders)
                      for i in range(order.size - 1) for j in range(i + 1, order.size)]
        improved = False
        done, batch = 0, 16
        while done < len(spans) and not improved:
            # the spans' trials in batches (each the whole path unwrapped), the first that
            # helps taken, as one trial after the other would
            trials = []
            for k, i, j in spans[done:done + batch]:
                order, trial = orders[k], orders.copy()
                trial[k] = np.concatenate([order[:i], order[i:j + 1][::-1], order[j + 1:]])
                trials.append(trial)
            visits = np.stack([np.concatenate([at + o for at, o in zip(first, trial,
                                                                        strict=True)])
                               for trial in trials])
            paths = _unwrap_paths(poses, visits, q_start, q_min, q_max)
            trial_costs = costs(paths)
            better = np.flatnonzero(trial_costs < best - 1e-12)
            if better.size:
                orders, best, improved = trials[better[0]], float(trial_costs[better[0]]), True
            done, batch = done + len(trials), 2 * batch
        if not improved:
            break
        path = whole(orders)
    ends = np.cumsum([b.shape[0] for b in blocks])[:-1]
    return orders, list(np.split(whole(orders), ends))


def _joint_cost(dq: np.ndarray) -> np.ndarray:
    """A full-turn joint's cost of moves dq (rad): |dq|, plus UNWIND_PENALTY x what exceeds
    half a turn (such a move is an unwinding: an equivalent angle would be nearer)."""
    size = np.abs(dq)
    return np.asarray(size + UNWIND_PENALTY * np.maximum(size - np.pi, 0.0))


def short_path(q: np.ndarray, q_start: np.ndarray, q_min: np.ndarray, q_max: np.ndarray,
               joint_speed: Rates = None) -> tuple[np.ndarray, np.ndarray]:
    """(order (N,) into q, the poses (N, n) in that order) of the shorter of two tours from
    q_start: the plain one, and the one that turns full-turn joints the short way round
    (`periodic`, then `unwrap_path`), by the real move time. Never longer than the plain
    tour."""
    q = np.asarray(q, float)
    plain = plan_tour(q, q_start, joint_speed)
    periodic = full_turn_joints(q_min, q_max)
    if not np.any(periodic) or q.shape[0] == 0:
        return plain, q[plain]
    around = plan_tour(q, q_start, joint_speed, periodic)
    unwrapped = unwrap_path(q[around], q_start, q_min, q_max)
    if path_time(unwrapped, q_start, joint_speed) < path_time(q[plain], q_start, joint_speed):
        return around, unwrapped
    return plain, q[plain]
