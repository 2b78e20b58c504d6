"""Pushing compensated zero offsets to the controller, with guard rails, and rolling back.

Compensation (docs/conventions.md): a fitted joint offset `delta_i` means
`q_true = q_cmd + delta_i`, so the new zero offset is `o_i_new = o_i + delta_i`.

Guard rails:
- joints whose offset the fit holds fixed (unidentifiable: the data cannot tell it apart
  from a frame) or that are not in the model keep their offset, and the plan says why;
- a correction larger than `max_correction_deg` (default 2 deg) on any pushed joint refuses
  the whole push unless `force`; so does a fit that did not converge;
- the controller's previous offsets and its rollback id are saved in the run folder
  (`push.json`) before anything else happens, so `hostpc rollback --run DIR` can undo it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from hostpc.errors import InputError
from hostpc.fitting import FitResult
from hostpc.methods.journal import write_json_atomic
from hostpc.methods.planning import joint_offset_names
from hostpc.robots.base import RobotAdapter

PUSH_FILE = "push.json"
DEFAULT_MAX_CORRECTION_DEG = 2.0


@dataclass(frozen=True)
class PushPlan:
    """old / delta / new: (n,) rad (delta zero where not pushed); sigma: (n,) rad (NaN where
    not identified); pushed: (n,) bool; notes: per joint, why it is not pushed (or "");
    refused: why the guard rail refuses the whole push, or None."""

    old: np.ndarray
    delta: np.ndarray
    new: np.ndarray
    sigma: np.ndarray
    pushed: np.ndarray
    notes: tuple[str, ...]
    refused: str | None = None
    max_correction_deg: float = DEFAULT_MAX_CORRECTION_DEG
    fitted: np.ndarray = field(default_factory=lambda: np.zeros(0))

    @property
    def anything(self) -> bool:
        """True if at least one joint would change."""
        return bool(np.any(self.pushed))

    def joints(self) -> list[dict[str, Any]]:
        """Per joint, JSON-ready, in degrees (for the result document and the summary)."""
        rows = []
        for j in range(self.old.size):
            fitted = float(self.fitted[j]) if self.fitted.size else float(self.delta[j])
            rows.append({
                "joint": j + 1,
                "old_deg": math.degrees(float(self.old[j])),
                "correction_deg": math.degrees(fitted) if np.isfinite(self.sigma[j]) else None,
                "sigma_deg": (math.degrees(float(self.sigma[j]))
                              if np.isfinite(self.sigma[j]) else None),
                "new_deg": math.degrees(float(self.new[j])),
                "pushed": bool(self.pushed[j]),
                "note": self.notes[j],
            })
        return rows


def plan_push(result: FitResult, old_offsets: np.ndarray,
              max_correction_deg: float = DEFAULT_MAX_CORRECTION_DEG, force: bool = False
              ) -> PushPlan:
    """Decide what to push from a fit (see the module docstring); nothing is written."""
    old = np.asarray(old_offsets, dtype=float)
    n = old.size
    names = result.names
    fitted = np.zeros(n)
    sigma = np.full(n, np.nan)
    pushed = np.zeros(n, dtype=bool)
    notes = []
    held = {d.fixed: d for d in result.unidentifiable}
    offset_names = joint_offset_names(n, result.problem.context.joint_labels)
    for j, name in enumerate(offset_names):
        if name not in names:
            notes.append("not in the model (joint_offsets not fitted)")
            continue
        k = names.index(name)
        if result.fixed[k]:
            direction = held.get(name)
            reason = "unidentifiable with these frames and poses; left unchanged"
            if direction is not None and len(direction.parameters) > 1:
                others = ", ".join(direction.parameters[1:4])
                reason = f"unidentifiable (not separable from {others}); left unchanged"
            notes.append(reason)
            continue
        fitted[j] = result.x[k]
        sigma[j] = result.std[k]
        pushed[j] = True
        notes.append("")
    delta = np.where(pushed, fitted, 0.0)
    refused = None
    limit = math.radians(max_correction_deg)
    too_big = pushed & (np.abs(delta) > limit)
    if np.any(too_big) and not force:
        j = int(np.argmax(np.where(too_big, np.abs(delta), 0.0)))
        refused = (f"joint {j + 1} correction {math.degrees(delta[j]):+.4f} deg exceeds the "
                   f"limit of {max_correction_deg:g} deg; check the cell and the data, and "
                   "rerun with --force to push anyway")
    elif not result.converged and not force:
        refused = (f"the fit did not converge ({result.message}); not pushing "
                   "(--force to push anyway)")
    return PushPlan(old=old, delta=delta, new=old + delta, sigma=sigma, pushed=pushed,
                    notes=tuple(notes), refused=refused, max_correction_deg=max_correction_deg,
                    fitted=fitted)


@dataclass(frozen=True)
class PushRecord:
    """What was written: previous and new offsets (n,) rad, the controller's rollback id."""

    previous: np.ndarray
    new: np.ndarray
    rollback_id: str
    pushed: tuple[bool, ...]

    def to_dict(self) -> dict[str, Any]:
        return {
            "rollback_id": self.rollback_id,
            "previous_offsets": self.previous.tolist(),
            "new_offsets": self.new.tolist(),
            "pushed": list(self.pushed),
        }


async def execute_push(robot: RobotAdapter, plan: PushPlan, run_dir: Path,
                       address: str) -> PushRecord:
    """Write plan.new to the controller and save push.json (previous offsets, rollback id).

    Raises InputError if the guard rail refused the plan (callers check `plan.refused`)."""
    if plan.refused:
        raise InputError(f"push refused: {plan.refused}")
    previous, rollback_id = await robot.set_offsets(plan.new)
    record = PushRecord(previous=np.asarray(previous, float), new=plan.new.copy(),
                        rollback_id=str(rollback_id),
                        pushed=tuple(bool(v) for v in plan.pushed))
    write_json_atomic(run_dir / PUSH_FILE, {"controller": address, **record.to_dict()})
    return record


def read_push_file(run_dir: str | Path) -> dict[str, Any]:
    """The push record of a run folder; InputError if the run pushed nothing."""
    import json

    path = Path(run_dir) / PUSH_FILE
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise InputError(f"{run_dir}: this run pushed no offsets (no {PUSH_FILE})") from None
    except (OSError, ValueError) as exc:
        raise InputError(f"{path}: cannot read ({exc})") from None
    if not isinstance(data, dict) or "rollback_id" not in data:
        raise InputError(f"{path}: no rollback_id")
    return data


async def rollback(robot: RobotAdapter, rollback_id: str,
                   previous: np.ndarray | None = None) -> tuple[np.ndarray, str]:
    """Restore the offsets replaced by the write `rollback_id`.

    If the controller no longer knows the id (it restarted) and `previous` is given, the
    previous offsets are written directly instead. Returns (offsets now (n,), how)."""
    from hostpc.transport import ControllerRefusedError

    try:
        now = await robot.rollback(rollback_id)
        return np.asarray(now, float), "rollback_id"
    except ControllerRefusedError as exc:
        if exc.code != "unknown_rollback" or previous is None:
            raise
    await robot.set_offsets(np.asarray(previous, float))
    return np.asarray(await robot.get_offsets(), float), "previous_offsets_written"
