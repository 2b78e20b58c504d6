"""The frozen values a diagnosis returns, and their JSON form (``Diagnosis.to_dict``).

JSON is in SI units (metres, radians) like every saved result; mm appear only in the CLI's
text and in the report. Names of effects, parameters and variables are exactly those of the
dataset contract (``q3``, ``tau2``, ``approach1``, ``t``, ``depth``, ``extra.NAME``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hostpc.diagnostics.adequacy import Adequacy, HeldOut
from hostpc.diagnostics.candidates import Candidate, SkippedCandidate
from hostpc.diagnostics.detectable import DetectableSize
from hostpc.diagnostics.interactions import Interaction
from hostpc.diagnostics.outliers import Outlier
from hostpc.diagnostics.residual_analysis import ResidualAnalysis
from hostpc.diagnostics.sample_names import whole_poses
from hostpc.diagnostics.separation import PairTest
from hostpc.fitting import FitResult
from hostpc.json_object import JsonObject

FORMAT = "zerocal-diagnosis/1"
#: delta BIC difference below which two candidates are tied (``ModelCheck.best_candidate``)
BIC_TIE = 2.0
JSON_INTERACTIONS = 25
#: the file that makes a folder a calibrate run (``hostpc.calibrate.journal``)
RUN_JOURNAL = "journal.jsonl"


def finite(value: float | None) -> float | None:
    """JSON-safe float: None for None, NaN and infinities."""
    return None if value is None or not math.isfinite(value) else float(value)


@dataclass(frozen=True, eq=False)  # holds arrays: compared by identity (__init__.py)
class ModelCheck:
    """One model checked: its fit, held-out residuals, verdict, candidates and interactions.

    candidates: best first; skipped: effects that could not be tried; interactions: best
    first; n_interaction_tests: how many (parameter, variable) pairs were tested; outliers:
    the samples found to be outliers, most significant first; cleaned: with outliers, the
    check of the same model fitted without them - the candidates and interactions of this
    check are that check's (an effect is not blamed for a bad sample).
    """

    fit: FitResult
    held_out: HeldOut | None
    adequacy: Adequacy
    candidates: tuple[Candidate, ...]
    skipped: tuple[SkippedCandidate, ...]
    interactions: tuple[Interaction, ...]
    n_interaction_tests: int
    outliers: tuple[Outlier, ...] = ()
    cleaned: ModelCheck | None = None

    @property
    def effects(self) -> tuple[str, ...]:
        return self.fit.problem.effect_names

    @property
    def ranked(self) -> ModelCheck:
        """The check the candidates were ranked on: ``cleaned`` with outliers, else this."""
        return self.cleaned if self.cleaned is not None else self

    @property
    def excluded(self) -> tuple[int, ...]:
        """Samples left out of the candidate ranking, the search and the ladder."""
        return tuple(sorted(o.sample for o in self.outliers))

    @property
    def best_candidate(self) -> Candidate | None:
        """The best significant candidate that costs no identifiable parameter, or None.

        Candidates whose delta BIC is within ``BIC_TIE`` of the best one's are a tie (the
        evidence between them is "not worth more than a bare mention", Kass & Raftery
        1995): among them the one whose effect as a whole (all its parameters) fits best
        is taken. After geometry, joint 2's compliance (c2 tau2) and encoder scale (s2 q2)
        can fit stereo data equally well on their own; compliance of every joint fits
        better than the scale of every joint when compliance is what is there."""
        taken = [c for c in self.candidates if c.taken]
        if not taken or taken[0].delta_bic is None:
            return taken[0] if taken else None
        best = taken[0].delta_bic
        tied = [c for c in taken if c.delta_bic is not None and c.delta_bic - best < BIC_TIE]
        return min(tied, key=lambda c: math.inf if c.delta_bic_full is None
                   else c.delta_bic_full)

    @property
    def costly_candidate(self) -> Candidate | None:
        """The best significant candidate that makes an identifiable parameter
        unidentifiable (never taken silently), or None."""
        return next((c for c in self.candidates if c.significant and c.unidentifiable), None)

    @property
    def significant_interactions(self) -> tuple[Interaction, ...]:
        return tuple(i for i in self.interactions if i.significant)


@dataclass(frozen=True, eq=False)  # holds arrays: compared by identity (__init__.py)
class LadderStep:
    """One rung of the ladder: the model, what was added to reach it (None for the start),
    and its in-sample and held-out residual norms (m), the held-out whitened RMS per scalar
    row (1 at the stated noise level), chi2/dof and verdict; removed: effects an earlier
    step added that this step's model no longer needs (dropped after the addition)."""

    step: int
    effects: tuple[str, ...]
    added: str | None
    rms: float
    max: float
    cv_rms: float | None
    cv_max: float | None
    cv_whitened_rms: float | None
    chi2_dof: float
    delta_bic: float | None
    free_parameters: int
    adequate: bool
    check: ModelCheck
    removed: tuple[str, ...] = ()

    @property
    def change(self) -> str | None:
        """What the step did, in words: ``backlash``, ``backlash, without encoder_scale``
        (None for the start)."""
        if self.added is None:
            return None
        return self.added + "".join(f", without {r}" for r in self.removed)

    def to_dict(self) -> JsonObject:
        return {
            "step": self.step, "effects": list(self.effects), "added": self.added,
            "removed": list(self.removed),
            "rms": self.rms, "max": self.max, "cv_rms": finite(self.cv_rms),
            "cv_max": finite(self.cv_max), "cv_whitened_rms": finite(self.cv_whitened_rms),
            "chi2_dof": finite(self.chi2_dof),
            "delta_bic": finite(self.delta_bic), "free_parameters": self.free_parameters,
            "adequate": self.adequate,
        }


@dataclass(frozen=True, eq=False)  # holds arrays: compared by identity (__init__.py)
class Diagnosis:
    """Everything ``diagnose`` found about one dataset and model.

    check: the current model's check; residuals: its residual analysis; ladder: the nested
    models fitted with ``ladder=True`` (else None; without the outlier samples when there
    are outliers); advice: plain sentences, most important first; alpha: the family-wise
    significance of every test; source: the dataset's path (for the commands in the
    advice), if known; ladder_stop: why the ladder stopped before the model was adequate, as
    a sentence (None when it did not, or without a ladder); detectable: each tried
    candidate's minimum detectable size with these poses (``detectable``); confounded:
    pairs of significant candidates neither of which is significant given the other
    (``separation``), with ``separate_command`` the command that measures what tells them
    apart.
    """

    check: ModelCheck
    residuals: ResidualAnalysis
    ladder: tuple[LadderStep, ...] | None
    advice: tuple[str, ...]
    alpha: float
    source: str | None
    plugins: tuple[str, ...]
    ladder_stop: str | None = None
    detectable: tuple[DetectableSize, ...] = ()
    confounded: tuple[PairTest, ...] = ()

    @property
    def run_folder(self) -> str | None:
        """The calibrate run the dataset came from: its folder, when it holds that run's
        journal; None for a dataset that did not come from a run (imported with `hostpc
        import`, written by hand, copied out of its run folder)."""
        folder = Path(self.source).parent if self.source else None
        return str(folder) if folder is not None and (folder / RUN_JOURNAL).is_file() else None

    def separate_command(self, pair: PairTest) -> str | None:
        """``hostpc calibrate --resume RUN --separate A,B`` for the run the dataset came
        from (``run_folder``); None without one: no run to resume."""
        run = self.run_folder
        return None if run is None else (
            f"hostpc calibrate --resume {run} --separate {','.join(pair.names)}")

    def separate_instruction(self, pair: PairTest) -> str:
        """What measures the poses that tell the pair apart: the command for a run's
        dataset; for one that did not come from a run, which poses to add (there is no
        run whose plan's pool `--separate` could choose from)."""
        command = self.separate_command(pair)
        if command is not None:
            return (f"{command} (plans the fewest extra poses that give both, prints their "
                    "predicted separation, measures them and tests again)")
        first, second = pair.names
        imported = self.check.fit.problem.dataset.extra_fields.get("source")
        csv = imported.get("csv") if isinstance(imported, dict) else None
        origin = (f"this dataset was imported from {csv}" if isinstance(csv, str) and csv
                  else "this dataset did not come from a calibrate run")
        return (f"{origin}, so there is no run for `hostpc calibrate --separate` to resume: "
                f"measure more poses where {first} and {second} predict different "
                "residuals (spread over every joint's range, not near the poses already "
                "measured), add them to the dataset and diagnose it again")

    # the headline numbers of the current model ------------------------------------------
    @property
    def fit(self) -> FitResult:
        return self.check.fit

    @property
    def adequate(self) -> bool:
        return self.check.adequacy.adequate

    @property
    def rms(self) -> float:
        return self.check.adequacy.rms

    @property
    def max(self) -> float:
        return self.check.adequacy.max

    @property
    def chi2_dof(self) -> float:
        return self.check.adequacy.chi2_dof

    @property
    def cv_rms(self) -> float | None:
        return self.check.adequacy.cv_rms

    @property
    def candidates(self) -> tuple[Candidate, ...]:
        return self.check.candidates

    @property
    def interactions(self) -> tuple[Interaction, ...]:
        return self.check.interactions

    @property
    def outliers(self) -> tuple[Outlier, ...]:
        return self.check.outliers

    @property
    def generated_effects(self) -> dict[str, str]:
        """Plugin source of each effect the ladder generated and added, by effect name."""
        from hostpc.diagnostics.auto_effects import generated_sources

        return generated_sources([t.effect for t in self.final.fit.problem.terms])

    @property
    def final(self) -> ModelCheck:
        """The last model of the ladder (the current model without a ladder)."""
        return self.ladder[-1].check if self.ladder else self.check

    def to_dict(self, max_interactions: int = JSON_INTERACTIONS) -> JsonObject:
        """One JSON document (see docs/diagnostics.md for the schema)."""
        check = self.check
        a = check.adequacy
        fit = check.fit
        shown = [i for i in check.interactions[:max_interactions]]
        shown += [i for i in check.interactions[max_interactions:] if i.significant]
        held = check.held_out
        document: JsonObject = {
            "format": FORMAT,
            "source": self.source,
            "method": fit.problem.method,
            "units": {"length": "m", "angle": "rad"},
            "n_samples": int(fit.residuals_raw.shape[0]),
            "measurement_size": int(fit.residuals_raw.shape[1]),
            "effects": list(check.effects),
            "plugins": list(self.plugins),
            "alpha": self.alpha,
            "adequate": a.adequate,
            "reasons": list(a.reasons),
            "outliers": [o.to_dict() for o in check.outliers],
            "outlier_poses": [  # whole poses among them, as the text groups them
                {"pose": pose, "samples": members} for pose, members in whole_poses(
                    [o.sample for o in check.outliers],
                    fit.problem.dataset.samples).items()],
            "rms": a.rms,
            "max": a.max,
            "cv_rms": finite(a.cv_rms),
            "cv_max": finite(a.cv_max),
            "cv_whitened_rms": finite(a.cv_whitened_rms),
            "cv_folds": a.cv_folds,
            "chi2": a.chi2,
            "dof": a.dof,
            "chi2_dof": finite(a.chi2_dof),
            "chi2_band": [finite(a.chi2_band[0]), finite(a.chi2_band[1])],
            "chi2_dof_with_calibration": (None if a.chi2_dof_with_calibration is None
                                          else finite(a.chi2_dof_with_calibration)),
            "chi2_p_value": finite(a.p_value),
            "noise": {"scale": finite(a.noise_scale), "rms": finite(a.noise_rms),
                      "expected_rms": finite(a.expected_noise_rms)},
            "candidates": [c.to_dict() for c in check.candidates],
            "skipped_candidates": [{"effect": s.effect, "reason": s.reason}
                                   for s in check.skipped],
            "interactions": [i.to_dict() for i in shown],
            "n_interaction_tests": check.n_interaction_tests,
            "residuals": {
                "norm": [float(v) for v in self.residuals.norms],
                "whitened_norm": [float(v) for v in self.residuals.whitened_norms],
                "raw": fit.residuals_raw.tolist(),
                "whitened": fit.residuals_whitened.tolist(),
                "held_out_norm": None if held is None else [float(v) for v in held.norms],
                "worst": [{"index": w.index, "norm": w.norm, "whitened_norm": w.whitened_norm,
                           "raw": list(w.raw)} for w in self.residuals.worst],
                "patterns": [
                    {"variable": p.variable, "chi2": p.chi2, "dof": p.dof,
                     "p_value": p.p_value, "significant": p.significant,
                     "centres": [finite(v) for v in p.centres],
                     "counts": [int(c) for c in p.counts],
                     "mean_raw": p.mean_raw.tolist(),
                     "mean_whitened": p.mean_whitened.tolist(),
                     **({"levels": list(p.levels)} if p.levels else {})}
                    for p in self.residuals.patterns
                ],
            },
            "fit": fit.to_dict(),
            "advice": list(self.advice),
            "detectable": [d.to_dict() for d in self.detectable],
            "confounded": [{**c.to_dict(), "next": self.separate_command(c),
                            "instruction": self.separate_instruction(c)}
                           for c in self.confounded],
        }
        if self.ladder is not None:
            document["ladder"] = [step.to_dict() for step in self.ladder]
            document["generated_effects"] = list(self.generated_effects)
        return document


def free_parameters(fit: FitResult) -> int:
    return int(np.count_nonzero(~fit.fixed))
