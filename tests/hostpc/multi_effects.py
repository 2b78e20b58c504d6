"""Several effects hidden at once: the cases, and what the ladder did with each (per step:
the effect added, chi2/dof, the zero offsets' error against the truth).

Shared by tests/hostpc/test_diagnose_multi_effects.py and bench/bench_diagnose_multi.py.

Magnitudes are physical and the same on both instruments: gravity compliance of joints 2
and 3 (2.0e-5 and 2.5e-5 rad/N m: 0.1 deg at the shoulder's 100 N m), 0.3-0.4 mm errors of
two link dimensions, 0.0086 deg backlash of joints 2 and 3, and the thermal expansion of
aluminium links (2.3e-5 /K) while the arm warms up by 8 K over an hour's run of 120 poses
(30 s a pose): the links grow by 0.1-0.2 mm from the first pose to the last.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass

import numpy as np

import hostpc
from hostpc.diagnostics import Diagnosis
from hostpc.fitting import FitResult
from hostpc.synthesize import SyntheticDataset
from tests.hostpc.diagnose_support import hidden_world_point, warm_stereo_dataset

COMPLIANCE = {"joint_compliance.c2": 2.0e-5, "joint_compliance.c3": 2.5e-5}
CASES: dict[str, dict[str, float]] = {
    "compliance+geometry": {**COMPLIANCE, "geometry.a2": 4e-4, "geometry.d4": 3e-4},
    "compliance+backlash+thermal": {**COMPLIANCE, "backlash.b2": 1.5e-4,
                                    "backlash.b3": 1.5e-4, "thermal_expansion.e": 2.3e-5},
}
#: K the arm warms up by over the run (only thermal_expansion sees it)
SWING = 8.0

MAKERS: dict[str, Callable[..., SyntheticDataset]] = {
    "stereo_target": warm_stereo_dataset, "world_point": hidden_world_point}


def hidden_effects(hidden: Mapping[str, float]) -> set[str]:
    return {name.split(".", 1)[0] for name in hidden}


def make(method: str, case: str, seed: int, noise: bool = True) -> SyntheticDataset:
    """The dataset of one case (``noise`` False: the same poses and truth, exact data)."""
    return MAKERS[method](CASES[case], seed, swing=SWING, noise=noise)


def offsets_error(fit: FitResult, truth: Mapping[str, float]) -> tuple[float, float]:
    """(worst |fitted - true| zero offset in rad, worst |fitted - true| / sigma) over the
    offsets the fit identifies."""
    rows = [(abs(fit.x[k] - truth[name]), fit.std[k]) for k, name in enumerate(fit.names)
            if name.startswith("joint_offsets.") and not fit.fixed[k]]
    return max(e for e, _ in rows), max(e / s for e, s in rows)


@dataclass(frozen=True)
class Step:
    added: str | None
    removed: tuple[str, ...]
    chi2_dof: float
    adequate: bool
    offsets_error: float  # rad, worst identified offset
    offsets_z: float  # worst |error| / sigma


@dataclass(frozen=True)
class Outcome:
    """What the ladder did with one dataset, and the final sizes against the truth.

    sizes: hidden parameter -> (fitted, sigma, reference): the reference is the truth, or for
    a geometry parameter the exact-data fit's value (geometry deltas are identified only in
    combinations, held ones at nominal: the exact fit is the truth in the fit's own terms).
    """

    diagnosis: Diagnosis
    steps: tuple[Step, ...]
    sizes: dict[str, tuple[float, float, float]]

    @property
    def added(self) -> list[str | None]:
        return [s.added for s in self.steps[1:]]

    def line(self) -> str:
        """One line: effects in order, final chi2/dof, offsets' error (deg) at each step."""
        order = " > ".join(str(s.added) + "".join(f" -{r}" for r in s.removed)
                           for s in self.steps[1:]) or "(nothing)"
        errors = " > ".join(f"{np.degrees(s.offsets_error):.4f} ({s.offsets_z:.1f} sd)"
                            for s in self.steps)
        worst = max((abs(f - r) / s for f, s, r in self.sizes.values()), default=0.0)
        return (f"{order}; final chi2/dof {self.steps[-1].chi2_dof:.3f} "
                f"{'adequate' if self.steps[-1].adequate else 'NOT adequate'}; sizes within "
                f"{worst:.2f} sd; offsets error deg {errors}")


def run_case(method: str, case: str, seed: int) -> Outcome:
    synthetic = make(method, case, seed)
    hidden = CASES[case]
    diagnosis = hostpc.diagnose(synthetic.dataset, ladder=True)
    assert diagnosis.ladder is not None
    steps = tuple(Step(s.added, s.removed, s.chi2_dof, s.adequate,
                       *offsets_error(s.check.fit, synthetic.truth)) for s in diagnosis.ladder)
    final = diagnosis.ladder[-1].check.fit
    reference = dict(hidden)
    if "geometry" in final.problem.effect_names:
        # held where the final fit holds them, at its values (a warm-started ladder step
        # holds a parameter at the value an earlier step gave it, not always at nominal)
        held = [n for n, fixed in zip(final.names, final.fixed, strict=True) if fixed]
        exact = hostpc.fit(make(method, case, seed, noise=False).dataset,
                           list(final.problem.effect_names), hold=held, cv_folds=0,
                           x0=np.where(final.fixed, final.x, 0.0))
        assert np.array_equal(exact.fixed, final.fixed)
        reference.update({n: float(v) for n, v in zip(exact.names, exact.x, strict=True)
                          if n.startswith("geometry.")})
    sizes = {name: (float(final.x[k]), float(final.std[k]), reference[name])
             for k, name in enumerate(final.names) if name in hidden and not final.fixed[k]}
    return Outcome(diagnosis, steps, sizes)
