"""Plain sentences from a diagnosis: the verdict, the noise, what is missing and the command
that adds it. Lengths in mm here (human text, docs/conventions.md)."""

from __future__ import annotations

import math
import re
from collections.abc import Sequence

import numpy as np

from hostpc.diagnostics.adequacy import Adequacy, implausible_geometry
from hostpc.diagnostics.candidates import Candidate
from hostpc.diagnostics.diagnosis import LadderStep, ModelCheck
from hostpc.diagnostics.interactions import Interaction
from hostpc.diagnostics.patterns import pattern_effect
from hostpc.diagnostics.residual_analysis import ResidualAnalysis
from hostpc.diagnostics.sample_names import name_samples, poses_text, whole_poses
from hostpc.display_units import quantity
from hostpc.errors import InputError
from hostpc.fitting.folds import pose_groups
from hostpc.model.problem import default_effects
from hostpc.model.registry import available_effects

#: fewer degrees of freedom than this: the advice says the samples are too few to judge
FEW_DOF = 10
#: the default folds of the held-out residuals (they need 2 samples per fold)
DEFAULT_FOLDS = 5

def mm(value: float | None) -> str:
    return "-" if value is None else f"{value * 1e3:.4f} mm"


def _joint(parameter: str | None) -> str:
    """The joint a per-joint parameter belongs to: "c2" -> "2", "left.c2" -> "left.2",
    "sin1_q4" -> "4"."""
    parts = (parameter or "").split(".")[1:]  # without the effect name
    match = re.search(r"(\d+)$", parts[-1]) if parts else None
    if not match:
        return "?"
    return (parts[0] + "." if len(parts) > 1 else "") + match.group(1)


def effects_option(check: ModelCheck, name: str) -> str:
    """The --effects value that gives the current model plus ``name``."""
    current = list(check.effects)
    try:
        defaults = default_effects(check.fit.problem.dataset)
    except InputError:  # a plugin's measurement model: name the whole model explicitly
        defaults = None
    if current == defaults:
        return f"+{name}"
    return ",".join(current + [name])


def command(check: ModelCheck, name: str, source: str | None, plugins: Sequence[str]) -> str:
    """The command that diagnoses the model with ``name`` added; without a dataset file (a
    Dataset given from Python) only its options, never a placeholder."""
    parts = ["hostpc diagnose", source] if source else []
    parts += ["--effects", effects_option(check, name)]
    parts += [f"--plugin {p}" for p in plugins]
    return " ".join(parts)


def candidate_sentence(check: ModelCheck, candidate: Candidate, source: str | None,
                       plugins: Sequence[str]) -> str:
    parameter = candidate.strongest[0] if candidate.strongest else None
    effect = type(candidate.fit.problem.term(candidate.effect).effect)  # type: ignore[union-attr]
    template = effect.advice
    if template is None:
        description = effect.description
        phrase = f"Residuals are explained by {candidate.effect}" + (
            f" ({description})" if description else "")
    else:
        phrase = template.format(j=_joint(parameter), parameter=parameter)
    a = check.ranked.adequacy
    delta_bic = "-" if candidate.delta_bic is None else f"{candidate.delta_bic:.1f}"
    evidence = (f"delta BIC {delta_bic}, chi2/dof {a.chi2_dof:.3f} -> "
                f"{candidate.chi2_dof:.3f}, held-out RMS {mm(a.cv_rms)} -> {mm(candidate.cv_rms)}")
    if a.cv_whitened_rms is not None and candidate.cv_whitened_rms is not None:
        evidence += (f" (whitened {a.cv_whitened_rms:.3f} -> {candidate.cv_whitened_rms:.3f} "
                     "sigma, the figure judged)")
    if check.outliers:
        evidence += f" ({without(check)})"
    implausible = implausible_geometry(candidate.fit)
    if implausible is not None:  # a unit slip fits as a shrunken robot: said, not advised
        evidence += f"; but with it {implausible}"
    return (f"{phrase}: add {candidate.effect} "
            f"({command(check, candidate.effect, source, plugins)}); {evidence}.")


def samples_text(indices: Sequence[int]) -> str:
    """'sample #3' or 'samples #3, #17'."""
    listed = ", ".join(f"#{k}" for k in indices)
    return f"sample {listed}" if len(indices) == 1 else f"samples {listed}"


def without(check: ModelCheck) -> str:
    """'without sample #17': what the ranking left out."""
    return f"without {samples_text(check.excluded)}"


def outlier_note(check: ModelCheck) -> str:
    """The outliers and what to do about them (diagnose's advice and `hostpc fit --effects
    auto` print it)."""
    outliers = check.outliers
    listed = ", ".join(f"#{o.sample} ({o.sigma:.3g} sigma)" for o in outliers)
    one = len(outliers) == 1
    head = (f"Sample {listed} is an outlier" if one else f"Samples {listed} are outliers")
    measurement = "that measurement" if one else "those measurements"
    poses = whole_poses([o.sample for o in outliers], check.fit.problem.dataset.samples)
    if poses:  # every sample of a pose: one measurement (its joint reading) to check
        every = sum(len(members) for members in poses.values()) == len(outliers)
        head += f", {'all of' if every else 'among them'} {poses_text(poses)}"
        if every:
            measurement = ("that pose's measurement" if len(poses) == 1
                           else "those poses' measurements")
    it = "it" if one else "them"
    loss = check.fit.loss
    fix = (f" (the {loss} loss of this fit already down-weights {it})" if loss != "linear"
           else ", or fit with --loss cauchy")
    return f"{head}: check {measurement}{fix}."


#: a few poses "carry most of chi2" when at most this fraction of the poses (at least one)
#: carries at least MOST_OF_CHI2 of the chi-square of the fit the candidates were ranked on
FEW_POSES = 0.1
MOST_OF_CHI2 = 0.5


def concentrated_sentence(check: ModelCheck) -> str | None:
    """When a few poses carry most of the chi-square of the ranked fit (without the named
    outliers): which, their share, and what to check (None when the excess is spread)."""
    fit = check.ranked.fit
    samples = check.fit.problem.dataset.samples
    dataset_index = np.setdiff1d(np.arange(samples.n), check.excluded)  # ranked -> dataset
    per_sample = np.sum(np.asarray(fit.residuals_whitened) ** 2, axis=1)
    total = float(np.sum(per_sample))
    if not total > 0 or per_sample.size != dataset_index.size:
        return None
    poses = pose_groups(samples)[dataset_index]
    per_pose = np.bincount(poses, weights=per_sample)
    n_poses = int(np.count_nonzero(np.bincount(poses)))
    order = np.argsort(-per_pose)
    needed = int(np.searchsorted(np.cumsum(per_pose[order]) / total, MOST_OF_CHI2)) + 1
    if needed > max(1, int(FEW_POSES * n_poses)):
        return None
    chosen = order[:needed]
    share = float(np.sum(per_pose[chosen])) / total
    members = dataset_index[np.isin(poses, chosen)]
    one = needed == 1
    return (f"the excess is not spread evenly: {needed} of {n_poses} "
            f"{'pose' if one else 'poses'} ({name_samples(members, samples)}; {members.size} "
            f"of {dataset_index.size} samples) {'carries' if one else 'carry'} "
            f"{100 * share:.0f} % of chi2. Check {'that pose' if one else 'those poses'}: "
            "the joint reading, the marker or target seen (a bumped or swapped one), a row "
            "copied or read twice; or fit with --loss cauchy.")


def outlier_sentence(check: ModelCheck) -> str:
    """The outliers, what to do about them, and what the rest of the diagnosis did."""
    it = "it" if len(check.outliers) == 1 else "them"
    return (f"{outlier_note(check)} The candidate effects, the effect-agnostic search, the "
            f"binned residuals and the ladder below leave {it} out, so no effect is blamed "
            f"for {it}.")


def needed_samples(check: ModelCheck) -> int:
    """Samples for three residual rows per parameter of the largest model tried (the model
    plus its largest candidate), and for the held-out folds."""
    m = check.fit.residuals_raw.shape[1]
    model = check.fit.problem.layout.size
    largest = max([model] + [c.fit.problem.layout.size for c in check.candidates])
    return max(math.ceil(3 * largest / m), 2 * DEFAULT_FOLDS)


def few_samples_problems(check: ModelCheck) -> list[str]:
    """Why the samples are too few to judge the model, as clauses (empty: they are not):
    fewer than FEW_DOF degrees of freedom, candidates that cannot be tested, too few samples
    for a held-out RMS. (No degrees of freedom at all: few_samples_sentence says so.)"""
    a = check.adequacy
    n_samples = check.fit.residuals_raw.shape[0]
    untestable = [c.effect for c in check.candidates if not c.testable]
    problems = []
    if a.dof < FEW_DOF:
        problems.append(f"{a.dof} degrees of freedom give a wide chi-square band "
                        f"[{a.chi2_band[0]:.3f}, {a.chi2_band[1]:.3f}]")
    if untestable:
        problems.append(f"{len(untestable)} of {len(check.candidates)} candidate effects "
                        f"cannot be tested ({', '.join(untestable)}: no degrees of freedom "
                        f"left with them)")
    if problems and a.cv_rms is None and n_samples < 2 * DEFAULT_FOLDS:
        problems.append("there are too few samples for a held-out RMS")
    return problems


def few_samples_sentence(check: ModelCheck) -> str | None:
    """A plain statement when the samples are too few to judge the model (None if not):
    no degrees of freedom left, fewer than FEW_DOF, or candidates that cannot be tested."""
    a = check.adequacy
    n_samples, m = check.fit.residuals_raw.shape
    needed = needed_samples(check)
    if a.dof <= 0:
        return (f"Too few samples to judge: {n_samples} samples give {n_samples * m} numbers "
                f"for {int((~check.fit.fixed).sum())} fitted parameters, so nothing can be "
                f"tested (no verdict, no candidate, no noise estimate). Measure at least "
                f"{needed} samples.")
    problems = few_samples_problems(check)
    if not problems:
        return None
    return (f"Too few samples to judge reliably ({n_samples} samples): "
            f"{'; '.join(problems)}. The verdict is weak evidence either way; measure at "
            f"least {needed} samples.")


def interaction_sentence(interaction: Interaction, check: ModelCheck,
                         plugins: Sequence[str] = ()) -> str:
    """"X varies with Y", what that is (asking the built-in effects and those of the
    plugins), and what to do about it."""
    head = (f"The effect-agnostic search finds: {interaction.sentence} "
            f"(score {interaction.score:.1f}, p = {interaction.p_value:.2g})")
    context = check.fit.problem.context
    if interaction.variable in context.categorical:
        return f"{head}: {group_sentence(interaction)}"
    effect = pattern_effect(interaction.parameter, interaction.variable, context,
                            available_effects(plugins).values())
    if effect is not None and all(e not in check.effects for e in effect.split(" or ")):
        return f"{head}: that is what {effect} models."
    return (f"{head}. If no built-in effect explains it, write one whose parameter makes "
            f"{interaction.parameter} depend on {interaction.variable} (docs/effects.md) and "
            f"add it with --plugin FILE --effects +NAME.")


#: a level is named as the one that is off only if its shift is this many times the
#: runner-up's (else the levels differ together: no one of them stands out)
STANDS_OUT = 1.5
#: levels listed with their shift at most (the largest); the others get one bound
LISTED_LEVELS = 8


def group_sentence(interaction: Interaction) -> str:
    """What a "parameter differs per level" finding says: which level (if one stands out:
    |shift| at least STANDS_OUT times the runner-up's), by how much (in display units)."""
    group = interaction.variable
    cause = (f"(a mis-surveyed or moved {group}, or a setup that changed between groups)")
    shifts = interaction.level_shifts
    if not shifts:
        return (f"the samples of one {group} disagree with the others {cause}; the binned "
                f"residuals name which.")
    unit = interaction.unit
    by_size = sorted(shifts, key=lambda item: -abs(item[1]))
    listed = set(by_size[:LISTED_LEVELS])
    values = ", ".join(f"'{level}' {quantity(v, unit)}" for level, v in shifts
                       if (level, v) in listed)
    if len(shifts) > LISTED_LEVELS:
        rest = max(abs(v) for _, v in by_size[LISTED_LEVELS:])
        values += (f"; the other {len(shifts) - LISTED_LEVELS} {group}s within "
                   f"{quantity(rest, unit, signed=False)}")
    per_level = (f"fitted per {group}, {interaction.parameter} would be {values} against "
                 f"the mean of the {len(shifts)} groups")
    if len(shifts) == 2:
        (first, a), (second, b) = shifts
        return (f"the samples of {group} {first} and {group} {second} disagree {cause}: "
                f"{per_level}, a difference of {quantity(a - b, unit)} "
                f"({first} - {second}); with two groups the data cannot say which of them "
                f"is off.")
    (level, top), (_, runner_up) = by_size[:2]
    if abs(top) >= STANDS_OUT * abs(runner_up):
        return (f"the samples of {group} {level} disagree with the others {cause}: "
                f"{per_level}.")
    return (f"the samples of the {group}s disagree; no one {group} stands out {cause}: "
            f"{per_level}.")


def chi2_position(adequacy: Adequacy) -> str:
    """Where chi2/dof lies against its band, in words that agree with the noise sentence:
    "inside its band", "below its band" (pessimistic covariances: still adequate) or
    "above its band"."""
    low, high = adequacy.chi2_band
    if adequacy.chi2_dof < low:
        return "below its band"
    return "above its band" if adequacy.chi2_dof > high else "inside its band"


def verdict_sentence(check: ModelCheck) -> str:
    a = check.adequacy
    model = ", ".join(check.effects)
    band = f"[{a.chi2_band[0]:.3f}, {a.chi2_band[1]:.3f}]"
    held = (f", held-out RMS {mm(a.cv_rms)} (in-sample {mm(a.rms)})"
            if a.cv_rms is not None else f", RMS {mm(a.rms)}")
    if a.dof <= 0:
        return (f"The model ({model}) cannot be judged: {'; '.join(a.reasons)}, "
                f"RMS {mm(a.rms)}.")
    if a.adequate:
        return (f"The model ({model}) is adequate: chi2/dof {a.chi2_dof:.3f} is "
                f"{chi2_position(a)} {band} and no missing effect is significant{held}.")
    return f"The model ({model}) is NOT adequate: {'; '.join(a.reasons)}{held}."


def noise_sentence(check: ModelCheck) -> str:
    """The noise measured and stated, in mm per sample, and their whitened ratio.

    The mm figures are RMS norms, dominated by each sample's noisiest axis; the ratio is
    sqrt(chi2/dof), every axis of every sample in units of its own stated noise. The two
    need not agree (an understated lateral noise barely moves the mm figure), so the ratio
    is labelled as the whitened one."""
    a = check.adequacy
    n_free = int((~check.fit.fixed).sum())
    if a.dof <= 0:
        return (f"Noise: cannot be estimated with no degrees of freedom left; the stated "
                f"covariances predict {mm(a.expected_noise_rms)} RMS per sample.")
    text = (f"Noise: {mm(a.noise_rms)} RMS per sample (corrected for {n_free} fitted "
            f"parameters); the stated covariances predict {mm(a.expected_noise_rms)}. "
            f"Whitened ratio {a.noise_scale:.2f} (measured / stated noise, every axis in "
            f"units of its own stated noise: sqrt(chi2/dof); the mm figures are dominated by "
            f"the noisiest axis, so their ratio can differ).")
    if chi2_position(a) == "below its band":
        text += (" chi2/dof is below its band: the stated covariances are pessimistic "
                 f"(about {1 / max(a.noise_scale, 1e-9):.2f} times too large).")
    return text


def ladder_sentences(check: ModelCheck, ladder: Sequence[LadderStep],
                     ladder_stop: str | None) -> list[str]:
    """What the ladder did, and why it stopped early if it did."""
    sentences = []
    last = ladder[-1]
    head = f"Ladder ({without(check)})" if check.outliers else "Ladder"
    path = " -> ".join(f"{mm(s.cv_rms if s.cv_rms is not None else s.rms)}" for s in ladder)
    added = [s.added for s in ladder if s.added]
    removed = [r for s in ladder for r in s.removed]
    if added:
        verdict = ("adequate" if last.adequate else
                   f"still NOT adequate: {'; '.join(last.check.adequacy.reasons)}")
        dropped = (f" (and dropping {', '.join(removed)} again: once the later effects were "
                   f"in, the model no longer needed {'them' if len(removed) > 1 else 'it'})"
                   if removed else "")
        sentences.append(f"{head}: adding {', '.join(added)}{dropped} takes the held-out RMS "
                         f"{path}; the final model is {verdict}.")
    elif not last.adequate and ladder_stop is None:
        sentences.append(f"{head}: no candidate effect is significant, so nothing was "
                         "added.")
    if ladder_stop is not None:
        sentences.append(f"{head} stopped: {ladder_stop}.")
    return sentences


def advise(check: ModelCheck, residuals: ResidualAnalysis, ladder: Sequence[LadderStep] | None,
           source: str | None, plugins: Sequence[str], ladder_stop: str | None = None
           ) -> tuple[str, ...]:
    """The advice, most important first: outliers, then the verdict, the noise, what is
    missing, where the residuals fail, and what the ladder did."""
    sentences = [outlier_sentence(check)] if check.outliers else []
    sentences += [verdict_sentence(check), noise_sentence(check)]
    few = few_samples_sentence(check)
    if few is not None:
        sentences.append(few)
    if check.adequacy.dof <= 0:
        return tuple(sentences)
    best = check.best_candidate
    if best is not None:
        sentences.append(candidate_sentence(check, best, source, plugins))
    costly = check.costly_candidate
    if costly is not None and costly.not_taken is not None:
        sentences.append(f"{costly.effect} is significant (p = {costly.p_value:.2g}) but "
                         f"{costly.not_taken}.")
    top = check.significant_interactions[:1]
    if top:
        sentences.append(interaction_sentence(top[0], check, plugins))
    ranked = check.ranked.adequacy
    if not ranked.adequate and ranked.dof > 0 and best is None and costly is None \
            and not top:
        few_poses = concentrated_sentence(check)
        sentences.append("No candidate effect and no parameter-variable pattern is "
                         "significant" + (f", but {few_poses}" if few_poses else
                                          ": the excess is spread evenly; check the stated "
                                          "covariances and the worst samples."))
    patterns = [p for p in residuals.patterns if p.significant][:3]
    if patterns:
        listed = ", ".join(f"{p.variable} (p = {p.p_value:.2g})" for p in patterns)
        sentences.append(f"Binned residuals change significantly with {listed}"
                         + (f" ({without(check)})." if check.outliers else "."))
        for pattern in patterns:
            if pattern.levels:  # a group label: say which group is off
                sentence = pattern.sentence
                sentences.append(f"{sentence[0].upper()}{sentence[1:]}: check that "
                                 f"{pattern.variable}, or let the fit estimate it.")
    if residuals.worst:
        worst = residuals.worst[0]
        sentences.append(f"Worst sample: #{worst.index}, {mm(worst.norm)} "
                         f"({worst.whitened_norm:.2f} sigma whitened).")
    if ladder:
        sentences += ladder_sentences(check, ladder, ladder_stop)
    return tuple(sentences)
