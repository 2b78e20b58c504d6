"""Where each joint's fitted zero offset comes from: the data, a hold, a prior, or nowhere.

The fit's per-joint status, the one input of a run's outcome (outcome.py) besides the
journal. Per joint offset parameter `joint_offsets.q<j>`:

- source "data": the measurements determine it (it may carry a prior too, see below);
- source "hold": `--hold` kept it at nominal: the value shown is the start, not a result;
- source "prior": it has a `--prior` and the data add less information about it than the
  prior does. THE RULE: the data determine a joint with a prior only if the fit's sigma is
  at most the prior's sigma / sqrt(2), i.e. the data's information 1/sigma_fit^2 -
  1/sigma_prior^2 is at least the prior's 1/sigma_prior^2. A prior-dominated joint is
  never shown as measured and never pushed (its value is the prior restated);
- source "none": the model has no such parameter, or the data cannot see it (an
  unidentifiable direction held at nominal, e.g. J6 with the tool frame estimated).

Only "data" joints are calibrated. `reason` says why a joint is not, `fix` what would make
it identifiable (`--known tool`, a cell reference). Pure: reads a fit (a FitResult or a
saved fit: `hostpc.fitting.result.FitVerdict`), touches no file.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from hostpc.display_units import quantity
from hostpc.fitting.identifiability import NullDirection
from hostpc.fitting.result import FitVerdict
from hostpc.model.joint_offsets import PushTable

PRIOR_DOMINATED_RATIO = 1.0 / math.sqrt(2.0)
"""A joint with a prior is determined by the data only if sigma_fit <= this x sigma_prior."""
FRAME_NAMES = ("base", "tool", "target")


@dataclass(frozen=True)
class JointSource:
    """The fit's verdict on one joint offset. joint: 1-based; label: the model's name
    (`q1`, `left.q3`); source: data | hold | prior | none; reason / fix: why it is not
    calibrated and what would determine it (None for a data joint)."""

    joint: int
    label: str
    source: str
    reason: str | None = None
    fix: str | None = None
    restored_from: str | None = None
    """The recording run of the cell reference whose frames alone identify this joint (its
    zero is restored to the zero it had at that run's frames); None: the measurements."""
    reference_zero: str | None = None
    """With `restored_from`, that reference's record of this joint (REFERENCE_ZEROS):
    "measured" (its recording run calibrated it), "as_found" (it did not: the zero as it
    was then) or "unknown" (a reference written before the record was kept)."""

    @property
    def calibrated(self) -> bool:
        return self.source == "data"


def prior_dominated(sigma: float, sigma_prior: float) -> bool:
    """THE RULE (module docstring): a joint with a prior of sigma_prior whose fitted (or
    predicted) sigma is `sigma` is determined by its prior, not by the data."""
    return not (math.isfinite(sigma) and sigma <= PRIOR_DOMINATED_RATIO * sigma_prior)


def _frames_of(parameters: tuple[str, ...]) -> list[str]:
    frames: list[str] = []
    for name in parameters:
        head = name.split(".", 1)[0]
        if head in FRAME_NAMES and head not in frames:
            frames.append(head)
    return frames


def _unidentifiable(direction: NullDirection | None) -> tuple[str, str]:
    """(reason, fix) of a joint offset held by an unidentifiable direction."""
    others = tuple(direction.parameters[1:]) if direction is not None else ()
    frames = _frames_of(others)
    if frames:
        what = " and ".join(frames)
        noun = "frame" if len(frames) == 1 else "frames"
        reason = (f"unidentifiable with the {what} {noun} estimated (not separable from "
                  f"{', '.join(others[:3])})")
        fix = f"--known {','.join(frames)} (or a cell reference that fixes the {what} {noun})"
        return reason, fix
    if others:
        return (f"unidentifiable (not separable from {', '.join(others[:3])})",
                "poses that move this joint independently, or a reference measurement")
    return ("unidentifiable with these frames and poses",
            "more varied poses, or a reference measurement")


def _prior_sigmas(result: FitVerdict) -> tuple[dict[str, float], set[str]]:
    """(prior sigma per parameter name, names held by --hold) of the fit's problem."""
    problem = result.problem
    if problem is None:
        return {}, set()  # a saved fit (offline push) carries no constraints
    from hostpc.fitting.priors import problem_constraints

    constraints = problem_constraints(problem)
    if constraints is None:
        return {}, set()
    sigmas = {p.name: float(p.sigma) for p in constraints.priors}
    held = {name for name, h in zip(problem.layout.names, constraints.held, strict=True) if h}
    return sigmas, held


def joint_sources(result: FitVerdict, n_joints: int) -> tuple[JointSource, ...]:
    """Per joint (n_joints of the controller), where its fitted offset comes from (see the
    module docstring)."""
    names = list(result.names)
    table = PushTable.for_controller(n_joints, result.joint_labels)
    held_by = {d.fixed: d for d in result.unidentifiable}
    prior_sigma, user_held = _prior_sigmas(result)
    out = []
    for j, (name, label) in enumerate(zip(table.names, table.labels, strict=True)):
        if name not in names:
            out.append(JointSource(j + 1, label, "none",
                                   "not in the model (joint_offsets not fitted)",
                                   "--effects +joint_offsets"))
            continue
        k = names.index(name)
        if name in user_held:
            out.append(JointSource(j + 1, label, "hold",
                                   "held at its nominal value by --hold (not measured)",
                                   f"drop --hold {name}"))
            continue
        if bool(result.fixed[k]):
            reason, fix = _unidentifiable(held_by.get(name))
            out.append(JointSource(j + 1, label, "none", reason, fix))
            continue
        sigma_prior = prior_sigma.get(name)
        std = float(np.asarray(result.std, float)[k])
        if sigma_prior is not None and prior_dominated(std, sigma_prior):
            assert result.problem is not None  # a prior comes from the fit's problem
            unit = result.problem.layout.units[k]  # rad, m for a prismatic joint
            out.append(JointSource(
                j + 1, label, "prior",
                f"determined by its --prior (+-{quantity(sigma_prior, unit, False)}), not by "
                f"the data (fit sigma {quantity(std, unit, False)})",
                "more poses that move this joint, or a tighter reference"))
            continue
        out.append(JointSource(j + 1, label, "data"))
    return tuple(out)
