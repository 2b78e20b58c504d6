"""Any size of motor swap: a declared swap's push limit, the controller's own offset limit,
and the coarse-to-fine staging of the measurement (issue 24, item 5).

A joint off by tens of degrees (a motor swapped, its encoder's zero anywhere) moves every
planned pose: the target leaves the cameras' view, the reflector the tracker's. The plan's
poses are joint values; the controller reaches ``q + error`` for a commanded ``q``, and the
fit's joint offset is that error. So the runner measures the plan once, fits, and when a
joint is estimated more than ``COARSE_DEG`` off it measures the same plan again with every
pose shifted by the estimate (commanded ``q - estimate``: the robot is where the plan meant
it to be), fits that stage alone, and repeats until the estimate moves less than
``SETTLED_DEG`` (at most ``MAX_STAGES`` extra stages). The final fit uses the last stage's
poses only. When more than a quarter of the plan's poses were lost (a sphere_probe touch
misses the 12.5 mm sphere after a 2 deg J1 error), ``LOST_DEG`` instead of ``COARSE_DEG``
starts the stages. When the plan's own poses gave too little to fit (fewer than a quarter
measured: a 15 deg swap) and a swap is declared, a coarse search comes first: the plan's
first pose is tried with the swapped joint shifted by +-1, +-2, ... deg
(``SEARCH_STEP_DEG``, up to --swap-limit) until it is measured, then on while it is: the
middle of the measured range is the first stage's shift (the first hit is a touch on the
flank). Each stage is journaled (`stage` event: its number, the estimate it is shifted by,
the index of its first pose), so a resume replays the stages and measures only what no
stage journaled yet. Undeclared, nothing is searched: the run ends with the command that
declares the swap (`lost_plan_line`).

A method opts in through `Method.staged` and follows the shift through its planning hook
`Method.set_joint_estimate` (stereo_target, world_point, sphere_probe: its contacts are
commanded less the estimate); dual_loop (a kinematic tree) does not.

`--swapped J3` (the station's ``swapped``) raises the push limit of that joint only to
``--swap-limit`` (default ``DEFAULT_SWAP_LIMIT_DEG``); the others keep ``--max-correction``.
The controller's own offset limit (``offset_limit``) is not zerocal's: a push it refuses
ends as a refusal that says so and what to do, journaled once, so a resume does not push
into it again unasked.
"""

from __future__ import annotations

import datetime as _dt
import math
from collections import Counter
from collections.abc import Awaitable, Callable, Sequence
from typing import Any

import numpy as np

from hostpc.calibrate.journal import Journal
from hostpc.calibrate.journal_events import Stage
from hostpc.calibrate.refusals import PushRefusal, resume_with
from hostpc.dataset import Dataset
from hostpc.errors import ControllerError, InputError
from hostpc.fitting import FitResult
from hostpc.methods.base import Method, Progress, RunSettings
from hostpc.model import joint_offsets
from hostpc.model.problem import build_problem

__all__ = ["DEFAULT_SWAP_LIMIT_DEG", "MAX_SWAP_LIMIT_DEG", "Staging", "controller_limit_refusal",
           "joint_limits_deg", "lost_plan_line", "parse_swapped", "swap_message"]

DEFAULT_SWAP_LIMIT_DEG = 45.0
"""The push limit of a joint declared swapped (--swap-limit), deg."""
MAX_SWAP_LIMIT_DEG = 180.0
"""The largest --swap-limit worth asking for: a joint's zero is at most half a turn off."""
COARSE_DEG = 3.0
"""A joint estimated farther off than this (deg) makes the runner measure again, shifted."""
LOST_FRACTION = 0.25
LOST_DEG = 0.2
"""When more than LOST_FRACTION of the plan's poses were lost (a sphere_probe contact
misses the 12.5 mm sphere after 2 deg on J1), a joint estimated more than LOST_DEG off
(deg) is enough to measure again, shifted."""
SETTLED_DEG = 0.05
"""The stages stop when no joint's estimate moved more than this (deg) since the last."""
MAX_STAGES = 3
"""Extra (shifted) stages at most, after the plan's own."""
SEARCH_STEP_DEG = 1.0
"""The coarse search's step (deg) on a declared swapped joint."""
STAGE_STRIDE = 100_000
"""Stage k's fit poses are journaled from index k * STAGE_STRIDE (the plan's own from 0,
its further poses, more_poses, right after them)."""


def parse_swapped(text: str | None, option: str = "--swapped") -> tuple[int, ...]:
    """`J3`, `3`, `J1,J6` -> (3,), (3,), (1, 6); InputError naming the option."""
    if not text:
        return ()
    joints = []
    for part in text.split(","):
        word = part.strip().upper().removeprefix("J")
        if not (word.isascii() and word.isdigit()) or int(word) < 1:  # not "²"
            raise InputError(f"{option} {text}: expected joints like J3 or J1,J6")
        joints.append(int(word))
    return tuple(sorted(set(joints)))


def joint_limits_deg(n: int, settings: RunSettings) -> np.ndarray:
    """(n,) push limit per joint, deg: --swap-limit for a declared swap, else
    --max-correction. InputError for a declared joint the robot does not have."""
    limits = np.full(n, float(settings.max_correction_deg))
    for joint in settings.swapped:
        if joint > n:
            raise InputError(f"--swapped J{joint}: the robot has {n} joints")
        limits[joint - 1] = float(settings.swap_limit_deg)
    return limits


def swap_message(settings: RunSettings) -> str | None:
    """The line that says a declared swap sized the push limit of its joints only."""
    if not settings.swapped:
        return None
    joints = ", ".join(f"J{j}" for j in settings.swapped)
    return (f"declared swapped: {joints}; push limit {settings.swap_limit_deg:g} deg for "
            f"{'that joint' if len(settings.swapped) == 1 else 'those joints'} only "
            f"(--swap-limit), {settings.max_correction_deg:g} deg for the others "
            "(--max-correction)")


def controller_limit_refusal(exc: ControllerError, run_dir: Any, *,
                             scenario: str | None = None,
                             refused_before: Sequence[str] = ()) -> PushRefusal | None:
    """The refusal of a push the controller refused for its own offset limit, or None
    for any other error. It says whose limit it is and what to do. scenario: a simulated
    run's scenario file (its ``server.offset_limit_rad`` is the limit, and a resume
    starts the simulated controller from that file); refused_before: the reasons of this
    run's earlier controller-limit refusals (the same one again: the limit was not
    raised, and the refusal says so instead of advising itself again)."""
    name = getattr(exc, "reason", None) or getattr(exc, "code", None)
    if name != "offset_limit":
        return None
    again = any(str(exc) in r for r in refused_before)
    head = (f"the controller's own offset limit refused the push ({exc})"
            + (" again, unchanged since the last refusal: it was not raised" if again else "")
            + ": this is the controller's setting, not zerocal's --max-correction or "
            f"--swap-limit; the fitted offsets are kept in {run_dir}/fit.json")
    if scenario:
        largest = largest_fitted_correction(run_dir)
        above = ("the largest correction" if largest is None else
                 f"the largest correction ({math.degrees(largest):.3g} deg, {largest:.3g} "
                 f"rad), e.g. {suggested_limit_rad(largest):g} rad")
        text = (f"{head}; the simulated controller's limit is server.offset_limit_rad in "
                f"{scenario} (a resume starts the simulated controller from that file): "
                f"raise it there above {above}, then push and verify with: "
                f"hostpc calibrate --resume {run_dir} --push")
    elif again:
        text = (f"{head}; pushing again meets the same refusal: raise the limit on the "
                "controller (its configuration, or the robot maker's tool), or set the "
                "joint's zero with the robot maker's zeroing procedure using the fitted "
                "offsets; once raised, push and verify with: "
                f"hostpc calibrate --resume {run_dir} --push")
    else:
        text = (f"{head}; raise the controller's offset limit (or set the joint's zero with "
                "the robot maker's zeroing procedure), then push and verify with: "
                f"hostpc calibrate --resume {run_dir} --push")
    return PushRefusal(text, "controller_limit", resume_with("--push"))


LIMIT_MARGIN = 1.25
"""A suggested controller limit: the largest fitted correction times this (rounded up)."""


def largest_fitted_correction(run_dir: Any) -> float | None:
    """The largest fitted joint offset correction (rad, absolute) in the run's fit.json,
    None if it has none (no file, or no joint offset)."""
    import json
    from pathlib import Path

    try:
        document = json.loads((Path(run_dir) / "fit.json").read_text(encoding="utf-8"))
        values = [abs(float(p["value"])) for name, p in document["parameters"].items()
                  if joint_offsets.is_offset(name)]
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        return None
    return max(values) if values else None


def suggested_limit_rad(largest: float) -> float:
    """A controller limit above `largest` (rad) with a margin (LIMIT_MARGIN), rounded up to
    0.01 rad."""
    return math.ceil(largest * LIMIT_MARGIN * 100.0 + 1e-9) / 100.0


def lost_plan_line(n_measured: int, n_planned: int, reasons: Sequence[str | None],
                   settings: RunSettings, run_dir: Any, *, staged: bool) -> str:
    """The one line of a run that measured too few of its poses to fit, ending with the
    next command: a joint far off loses every pose (a sphere_probe touch misses the sphere
    after a 15 deg swap), and only a declared swap searches for it."""
    counts = Counter(str(r) for r in reasons if r)
    why = f" (mostly: {counts.most_common(1)[0][0]})" if counts else ""
    line = f"only {n_measured} of {n_planned} poses measured{why}; nothing to fit"
    if not staged:
        return line + " (see the skipped reasons in journal.jsonl)"
    if not settings.swapped:
        return (line + "; if a joint's zero is far off (a motor swapped or re-mastered), "
                "declare that joint, and the run searches for it (the data do not say which "
                f"joint: replace JN with it): hostpc calibrate --resume {run_dir} --swapped JN")
    joints = ",".join(f"J{j}" for j in settings.swapped)
    limit = float(settings.swap_limit_deg)
    if limit >= MAX_SWAP_LIMIT_DEG:  # searched half a turn: the declaration is wrong
        return (line + f"; the search of the swapped {joints} found nothing up to "
                f"{limit:g} deg (the largest limit): {joints} is probably not the joint "
                "whose motor was swapped; declare the swapped joint instead (replace JN with "
                f"it): hostpc calibrate --resume {run_dir} --swapped JN --swap-limit "
                f"{DEFAULT_SWAP_LIMIT_DEG:g}")
    farther = min(2.0 * limit, MAX_SWAP_LIMIT_DEG)
    return (line + f"; the search of the swapped {joints} found nothing up to "
            f"{limit:g} deg: if {joints} is the swapped joint, search farther: "
            f"hostpc calibrate --resume {run_dir} --swap-limit {farther:g} (else declare the "
            f"swapped joint instead: --swapped JN --swap-limit {limit:g}, JN the joint)")


def _now() -> str:
    return _dt.datetime.now(_dt.UTC).isoformat(timespec="milliseconds")


AcquireFn = Callable[[np.ndarray, np.ndarray, int], Awaitable[np.ndarray]]
"""(commanded poses (N, n), where the robot is, first journal index) -> where it is."""
FitFn = Callable[[int], tuple[FitResult, Dataset]]
"""first journal index of a stage -> the fit of that stage's poses, and its dataset."""
EstimateFn = Callable[[FitResult], np.ndarray]
"""A fit -> (n,) joint offset estimate, rad (zero where not identified)."""
TryFn = Callable[[np.ndarray, np.ndarray], Awaitable[tuple[bool, np.ndarray]]]
"""(one commanded pose (n,), where the robot is) -> (measured?, where it is); not
journaled (the coarse search)."""


class Staging:
    """Coarse to fine (the module docstring); one per run. `first` is the journal index
    of the stage the final fit uses (0: the plan's own poses, nothing staged). The
    method's model follows the shift (`Method.set_joint_estimate`)."""

    def __init__(self, method: Method, journal: Journal, progress: Progress,
                 q_min: np.ndarray, q_max: np.ndarray) -> None:
        self.method = method
        self.journal = journal
        self.progress = progress
        self.q_min = np.asarray(q_min, float)
        self.q_max = np.asarray(q_max, float)
        self.first = 0
        self.estimate: np.ndarray | None = None  # the last stage's shift, rad
        self.last_fit: tuple[int, tuple[FitResult, Dataset]] | None = None
        """The last fit run() made and the `first` of its stage: the runner reuses it."""

    def shifted(self, q_plan: np.ndarray, pushed: np.ndarray | None = None) -> np.ndarray:
        """Further poses of a staged run commanded like its last stage (less what was
        pushed since: `pushed`, (n,) rad); unchanged when nothing was staged."""
        if self.estimate is None:
            return q_plan
        return self._shift(q_plan, self.estimate - (0.0 if pushed is None else pushed))

    def reading_after_push(self, q_now: np.ndarray, pushed: np.ndarray) -> np.ndarray:
        """Where a staged run's robot reads now that `pushed` ((n,) rad) is in the
        controller (the same place reads q + pushed; a 15 deg push is not a rounding
        error); unchanged when nothing was staged."""
        return q_now if self.estimate is None else np.asarray(q_now, float) + pushed

    def start_vector(self, dataset: Dataset, settings: RunSettings) -> np.ndarray | None:
        """The fit's start: the joint offsets at the current stage's shift (a fit started
        15 deg away can end in another minimum), the rest zero; None unstaged."""
        if self.estimate is None:
            return None
        layout = build_problem(dataset, settings.effects, plugins=settings.plugins).layout
        x0 = np.zeros(layout.size)
        for j, value in enumerate(self.estimate):
            name = joint_offsets.offset_name(f"q{j + 1}")
            if name in layout.names:
                x0[layout.index(name)] = value
        return x0

    def _shift(self, q_plan: np.ndarray, estimate: np.ndarray, new_stage: bool = False
               ) -> np.ndarray:
        """The poses commanded so the robot reaches them when its joints are off by
        `estimate` (within the controller's joint limits); the method told so."""
        self.method.set_joint_estimate(estimate, new_stage)
        q = np.asarray(q_plan, float) - estimate[None, :]
        if self.q_min.size == q.shape[1] and self.q_max.size == q.shape[1]:
            q = np.clip(q, self.q_min, self.q_max)
        return q

    async def run(self, q_plan: np.ndarray, q_now: np.ndarray, acquire: AcquireFn,
                  fit_stage: FitFn, estimate_of: EstimateFn, settings: RunSettings,
                  try_pose: TryFn) -> np.ndarray:
        """After the plan's own poses were measured: stage while a joint is far off or the
        estimate still moves; returns where the robot is. Journaled stages are replayed
        (their poses measured only where missing), never re-planned or searched again."""
        journaled = {e.number: e for e in self.journal.events(Stage)}
        estimate = np.zeros(q_plan.shape[1])
        for number in range(1, MAX_STAGES + 1):
            event = journaled.get(number)
            if event is None:
                measured = self._measured()
                if number == 1 and 4 * measured < q_plan.shape[0] and settings.swapped:
                    found, q_now = await self._search(q_plan[0], q_now, settings, try_pose)
                    if found is None:
                        break
                    new = found
                elif measured < 3:
                    break  # nothing to fit: the runner says so
                else:
                    self.last_fit = (self.first, fit_stage(self.first))
                    new = estimate_of(self.last_fit[1][0])
                moved = float(np.max(np.abs(new - estimate))) if new.size else 0.0
                far = float(np.max(np.abs(new))) if new.size else 0.0
                limit = COARSE_DEG if number == 1 else SETTLED_DEG
                if number == 1 and self._measured() < (1.0 - LOST_FRACTION) * q_plan.shape[0]:
                    limit = LOST_DEG  # the poses were lost to a smaller error
                if (far if number == 1 else moved) <= math.radians(limit):
                    break
                first = number * STAGE_STRIDE
                self.journal.append(Stage(number=number, first=first, at=_now(),
                                          estimate=tuple(float(v) for v in new)))
                self.progress.message(
                    f"stage {number}: joints estimated off by "
                    + ", ".join(f"J{j + 1} {math.degrees(v):+.3f}" for j, v in enumerate(new)
                                if abs(v) > math.radians(SETTLED_DEG))
                    + " deg; measuring the plan again with its poses shifted by that "
                    "estimate (coarse to fine)")
                estimate = new
            else:
                estimate = np.asarray(event.estimate, float)
                first = event.first
            before = (self.first, self.estimate)
            self.first, self.estimate = first, estimate
            q_now = await acquire(self._shift(q_plan, estimate, new_stage=True), q_now,
                                  first)
            if self._measured() < 3:  # this stage lost everything: the last one stands
                self.first, self.estimate = before
                self.progress.message(f"stage {number} measured too little; the fit uses "
                                      "the stage before")
                self.method.set_joint_estimate(
                    np.zeros_like(estimate) if self.estimate is None else self.estimate,
                    new_stage=True)
                break
        return q_now

    def _measured(self) -> int:
        """Poses measured in the current stage."""
        return sum(r.ok for r in self.journal.records("fit")
                   if self.first <= r.index < self.first + STAGE_STRIDE)

    async def _search(self, q_pose: np.ndarray, q_now: np.ndarray, settings: RunSettings,
                      try_pose: TryFn) -> tuple[np.ndarray | None, np.ndarray]:
        """The coarse search (module docstring): the first shift of a declared swapped
        joint at which `q_pose` is measured, or None; and where the robot is."""
        steps = int(math.floor(settings.swap_limit_deg / SEARCH_STEP_DEG))
        joints = [j - 1 for j in settings.swapped if j <= q_pose.size]
        self.progress.message(
            "too few poses measured for a fit: searching the swapped "
            + ", ".join(f"J{j + 1}" for j in joints)
            + f" in steps of {SEARCH_STEP_DEG:g} deg up to {settings.swap_limit_deg:g} deg")
        for step in range(1, steps + 1):
            for sign in (1.0, -1.0):
                for joint in joints:
                    estimate = np.zeros(q_pose.size)
                    estimate[joint] = sign * math.radians(step * SEARCH_STEP_DEG)
                    ok, q_now = await try_pose(self._shift(q_pose[None, :], estimate)[0],
                                               q_now)
                    if not ok:
                        continue
                    # the first hit is at the edge (a touch on the sphere's flank): go on
                    # while it is measured, and take the middle of the measured range
                    last = estimate.copy()
                    for _ in range(steps - step):
                        further = last.copy()
                        further[joint] += sign * math.radians(SEARCH_STEP_DEG)
                        ok, q_now = await try_pose(
                            self._shift(q_pose[None, :], further)[0], q_now)
                        if not ok:
                            break
                        last = further
                    self.method.set_joint_estimate(np.zeros(q_pose.size))
                    return 0.5 * (estimate + last), q_now
        self.method.set_joint_estimate(np.zeros(q_pose.size))
        self.progress.message("the search found no shift at which the first pose is "
                              "measured")
        return None, q_now
