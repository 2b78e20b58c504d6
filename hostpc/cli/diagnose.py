"""`hostpc diagnose DATASET`: is the model adequate, where does it fail, what is missing.

Exit codes (a CI job can gate on them, like grep's): ``EXIT_ADEQUATE`` 0 the model named
by ``--effects`` is adequate; ``EXIT_NOT_ADEQUATE`` 1 it is not, or the samples are too
few to judge it (the ladder's last step never changes this: it is advice); ``EXIT_ERROR`` 2
bad input (a missing or malformed dataset, an unknown effect, a bad option). Every error
of hostpc ends as exit 2 here, so 1 always means "ran, and the model failed".
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from hostpc.cli.fit import add_constraint_options, add_model_options
from hostpc.cli.format import repeated_lines
from hostpc.cli.robot_options import add_robot_override, robot_options
from hostpc.diagnostics.advice import mm, without
from hostpc.diagnostics.sample_names import poses_text, whole_poses
from hostpc.errors import InputError, ZerocalError

if TYPE_CHECKING:
    from hostpc.diagnostics import Diagnosis, LadderStep, ModelCheck

TOP_INTERACTIONS = 10
EXIT_ADEQUATE = 0
EXIT_NOT_ADEQUATE = 1
EXIT_ERROR = 2


def register(subparsers: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    parser = subparsers.add_parser(
        "diagnose",
        help="compare the model with the measurements and find the missing effect",
        description=(
            "Fit the model to a dataset, judge whether it is adequate (chi-square against its "
            "band, held-out RMS), show where it fails (residuals against every recorded "
            "variable), rank the effects that could be missing, and search for any parameter "
            "that varies with any variable. Exit code: 0 adequate, 1 not adequate (or too "
            "few samples to judge), 2 bad input. See docs/diagnostics.md."
        ),
    )
    parser.add_argument("dataset", help="dataset file (zerocal-dataset/1 JSON)")
    add_model_options(parser)
    add_constraint_options(parser)
    add_robot_override(parser)
    parser.add_argument("--ladder", action="store_true",
                        help="fit the nested models, adding the best candidate while it is "
                        "significant and lowers the whitened held-out RMS, and show each step")
    parser.add_argument("--candidates", metavar="LIST",
                        help="comma-separated effects to try (default: every effect that "
                        "applies; frames such as tool are part of the model, not candidates)")
    parser.add_argument("--alpha", type=float, default=None,
                        help="family-wise significance of each family of tests "
                        "(default 0.001)")
    parser.add_argument("--write-plugins", metavar="DIR",
                        help="with --ladder: write every effect the ladder generated from a "
                        "'parameter varies with variable' pattern as a plugin file DIR/NAME.py "
                        "(load it with --plugin)")
    parser.add_argument("--json", action="store_true", help="print one JSON document")
    parser.add_argument("--report", metavar="FILE.html",
                        help="also write a self-contained HTML report")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Diagnose, print, and return EXIT_ADEQUATE or EXIT_NOT_ADEQUATE; any hostpc error
    leaves as an InputError (exit EXIT_ERROR) so that 1 never means a failure to run."""
    try:
        return _run(args)
    except InputError:
        raise
    except ZerocalError as exc:
        raise InputError(str(exc)) from exc


def _units_first(diagnosis: Diagnosis, path: str) -> Diagnosis:
    """The diagnosis with a unit slip of its dataset (hostpc.cli.units_hint, as `hostpc
    import` and `hostpc fit` name it) as the first advice: numbers read in the wrong unit
    look like an effect (radians read as degrees: an encoder scale), so before any effect
    is added, the units are checked."""
    from hostpc.cli.units_hint import declared_angle_unit, declared_length_unit, slip_hint
    from hostpc.dataset.kind_registry import csv_row_kinds

    problem = diagnosis.check.fit.problem
    if problem.dataset.method not in csv_row_kinds():  # no world-frame points: no file read
        return diagnosis
    slip = slip_hint(problem.dataset, problem.context.chain, declared_length_unit(path),
                     declared_angle_unit(path))
    if slip is None:
        return diagnosis
    first = (f"Check the units first: {slip}; the effects advised below may only fit "
             "numbers read in the wrong unit.")
    return dataclasses.replace(diagnosis, advice=(first, *diagnosis.advice))


def _run(args: argparse.Namespace) -> int:
    from hostpc.diagnostics import DEFAULT_ALPHA, diagnose

    if args.cv_folds < 0:
        raise InputError(f"--cv-folds {args.cv_folds}: must not be negative")
    candidates = None
    if args.candidates:
        candidates = [c.strip() for c in args.candidates.split(",") if c.strip()]
    source: Any = args.dataset
    if args.prior or args.hold or args.robot:
        from hostpc.cli.robots import load_dataset_as_asked
        from hostpc.fitting.priors import with_constraints

        source = with_constraints(load_dataset_as_asked(args.dataset, args), args.prior,
                                  args.hold)
    diagnosis = diagnose(
        source, args.effects, plugins=args.plugin, ladder=args.ladder,
        candidates=candidates, alpha=DEFAULT_ALPHA if args.alpha is None else args.alpha,
        cv_folds=args.cv_folds, loss=args.loss, source=args.dataset,
        data_options=robot_options(args),
    )
    diagnosis = _units_first(diagnosis, args.dataset)
    if args.report:
        from hostpc.report import write_report

        try:
            write_report(args.report, diagnosis)
        except OSError as exc:
            raise InputError(f"--report {args.report}: cannot write it "
                             f"({exc.strerror or exc})") from exc
    written = write_plugins(args.write_plugins, diagnosis) if args.write_plugins else []
    if args.json:
        # one write: json.dump would write each of its ~10^4 pieces
        sys.stdout.write(json.dumps(diagnosis.to_dict(), indent=2, allow_nan=False))
        sys.stdout.write("\n")
    else:
        print(format_diagnosis(diagnosis))
        for line in repeated_lines(diagnosis.check.fit):
            print(line)
        if args.report:
            print(f"\nreport written to {args.report}")
        for path in written:
            print(f"plugin written to {path} (load it with --plugin {path} --effects "
                  f"+{path.stem})")
    return EXIT_ADEQUATE if diagnosis.adequate else EXIT_NOT_ADEQUATE


def write_plugins(directory: str, diagnosis: Diagnosis) -> list[Path]:
    """Write each generated effect of the ladder as DIR/NAME.py; the paths written."""
    if diagnosis.ladder is None:
        raise InputError("--write-plugins needs --ladder (the ladder generates the effects)")
    target = Path(directory)
    written = []
    try:
        target.mkdir(parents=True, exist_ok=True)
        for name, source in diagnosis.generated_effects.items():
            path = target / f"{name}.py"
            path.write_text(source, encoding="utf-8")
            written.append(path)
    except OSError as exc:
        raise InputError(f"--write-plugins {directory}: cannot write it "
                         f"({exc.strerror or exc})") from exc
    return written


def _p(value: float | None) -> str:
    return "-" if value is None or not math.isfinite(value) else f"{value:.2g}"


def _sigma(value: float | None) -> str:
    return "-" if value is None else f"{value:.3f}"


def cell(value: float | str | None, width: int, decimals: int = 4) -> str:
    """A number right-aligned in ``width`` characters, at least one of them a leading space
    so that columns never run together: fixed-point with ``decimals``, or scientific when
    that is too wide (9186383.132 -> ' 9.19e+06'); '-' for None and NaN; text as is."""
    if isinstance(value, str):
        text = value
    elif value is None or not math.isfinite(value):
        text = "-"
    else:
        text = f"{value:.{decimals}f}"
        digits = max(width - 7, 0)
        while len(text) > width - 1 and digits >= 0:
            text = f"{value:.{digits}e}"
            digits -= 1
    return " " + text.rjust(width - 1)


def name_cell(text: str, width: int) -> str:
    """Left-aligned text in ``width`` characters, followed by at least one space."""
    return text.ljust(width - 1) + " "


def _mm_cell(value: float | None, width: int = 10) -> str:
    return cell(None if value is None else value * 1e3, width)


def verdict_word(check: ModelCheck) -> str:
    a = check.adequacy
    if a.dof <= 0:
        return "cannot judge (too few samples)"
    return "adequate" if a.adequate else "NOT adequate"


def format_diagnosis(diagnosis: Diagnosis) -> str:
    """Human-readable text of a diagnosis (mm; see docs/diagnostics.md)."""
    check = diagnosis.check
    a = check.adequacy
    fit = check.fit
    n_samples = fit.residuals_raw.shape[0]
    head = f"diagnose {diagnosis.source}" if diagnosis.source else "diagnose"
    lines = [
        f"{head}: method {fit.problem.method}, {n_samples} samples, "
        f"model {', '.join(check.effects)}",
        f"verdict: {verdict_word(check)}",
    ]
    if a.dof > 0:
        inside = ("" if a.chi2_dof_with_calibration is None else
                  f", {a.chi2_dof_with_calibration:.3f} with the camera calibration's "
                  "covariance, the one judged")
        lines.append(f"  chi2/dof {a.chi2_dof:.3f}{inside} (band {a.chi2_band[0]:.3f}.."
                     f"{a.chi2_band[1]:.3f} for {a.dof} dof, p = {_p(a.p_value)})")
    else:
        lines.append(f"  chi2/dof - ({a.dof} degrees of freedom)")
    lines.append(f"  in-sample RMS {mm(a.rms)}, max {mm(a.max)}")
    if a.cv_rms is not None:
        lines.append(f"  held-out ({a.cv_folds}-fold) RMS {mm(a.cv_rms)}, max {mm(a.cv_max)}, "
                     f"whitened {_sigma(a.cv_whitened_rms)} sigma (1 = the stated noise)")
    if a.dof > 0:
        lines.append(f"  noise {mm(a.noise_rms)} per sample, corrected for the fitted "
                     f"parameters (the stated covariances predict {mm(a.expected_noise_rms)});"
                     f" whitened ratio {a.noise_scale:.3f} (1 = the stated noise)")
    for reason in a.reasons:
        lines.append(f"  - {reason}")
    worst = ", ".join(f"#{w.index} {w.whitened_norm:.2f} sigma ({mm(w.norm)})"
                      for w in diagnosis.residuals.worst[:5])
    lines += ["", f"worst samples: {worst}"]
    if check.outliers:
        poses = whole_poses([o.sample for o in check.outliers],
                            check.fit.problem.dataset.samples)
        lines.append("outliers: " + ", ".join(f"#{o.sample} {o.sigma:.3g} sigma "
                                              f"(p = {_p(o.p_value)})" for o in check.outliers)
                     + (f"; {poses_text(poses)}" if poses else "")
                     + f"; left out below ({without(check)})")
    lines += ["", "residuals binned against each variable (* significant):"]
    for pattern in diagnosis.residuals.patterns:
        mark = "*" if pattern.significant else " "
        lines.append(f"  {mark} {name_cell(pattern.variable, 15)}chi2"
                     f"{cell(pattern.chi2, 10, 1)} / {pattern.dof:<3} p = {_p(pattern.p_value)}")
        if pattern.levels and pattern.significant:
            lines.append(f"      {pattern.sentence}")
    base_sigma = check.ranked.adequacy.cv_whitened_rms
    folds = (f": sigma, the whitened held-out RMS, below the current model's "
             f"{base_sigma:.3f} on its {a.cv_folds} folds" if a.cv_folds and base_sigma
             else "")
    lines += ["", "candidate effects (best first; * significant and better held out"
              f"{folds}; each row's figures are one model's):",
              f"    {name_cell('effect', 24)}{'dBIC':>9}{'dBIC all':>10}{'RMS mm':>10}"
              f"{'held-out':>10}{'sigma':>8}{'chi2/dof':>10}{'p':>11}"]
    for c in check.candidates:
        mark = "*" if c.significant else " "
        lines.append(f"  {mark} {name_cell(c.effect, 24)}{cell(c.delta_bic, 9, 1)}"
                     f"{cell(c.delta_bic_full, 10, 1)}{_mm_cell(c.rms)}{_mm_cell(c.cv_rms)}"
                     f"{cell(c.cv_whitened_rms, 8, 3)}{cell(c.chi2_dof, 10, 3)}"
                     f"{cell(_p(c.p_value) if c.testable else 'untestable', 11)}")
        if c.not_taken is not None and c.not_taken.startswith(("significant", "adding")):
            lines.append(f"      not taken: {c.not_taken}")
    for s in check.skipped:
        lines.append(f"    {name_cell(s.effect, 24)}skipped: {s.reason}")
    lines += ["", f"parameter varies with variable (top {TOP_INTERACTIONS} of "
              f"{check.n_interaction_tests}; * significant):"]
    for i in check.interactions[:TOP_INTERACTIONS]:
        mark = "*" if i.significant else " "
        lines.append(f"  {mark} {name_cell(i.sentence, 45)}score{cell(i.score, 7, 1)}  "
                     f"p = {_p(i.p_value)}")
    if diagnosis.ladder:
        lines += ["", "ladder:" + (f" ({without(check)})" if check.outliers else ""),
                  ladder_header()]
        lines += [ladder_row(step) for step in diagnosis.ladder]
        if diagnosis.ladder_stop:
            lines.append(f"  stopped: {diagnosis.ladder_stop}")
    if diagnosis.detectable:
        noise = f"; the noise {without(check)}" if check.outliers else ""
        lines += ["", f"what these poses can see (80 % power at the candidates' threshold"
                      f"{noise}):"]
        lines += [f"  {d.sentence}" for d in diagnosis.detectable]
    if diagnosis.confounded:
        lines += ["", "confounded candidates (neither significant given the other):"]
        for pair in diagnosis.confounded:
            lines.append(f"  {pair.sentence}")
            if pair.gain_sentence is not None:
                lines.append(f"  {pair.gain_sentence}")
            lines.append(f"  separate them: {diagnosis.separate_instruction(pair)}")
    lines += ["", "advice:"] + [f"  - {sentence}" for sentence in diagnosis.advice]
    return "\n".join(lines)


def ladder_header() -> str:
    """The ladder table's header (the columns of ``ladder_row``)."""
    return (f"  {name_cell('step', 5)}{name_cell('added', 24)}{'RMS mm':>10}{'held-out':>10}"
            f"{'max':>10}{'sigma':>8}{'chi2/dof':>10}  verdict")


def ladder_row(step: LadderStep) -> str:
    """One ladder step in fixed-width columns (scientific notation where a value is too
    wide for its column)."""
    return (f"  {name_cell(str(step.step), 5)}{name_cell(step.change or '(current model)', 24)}"
            f"{_mm_cell(step.rms)}{_mm_cell(step.cv_rms)}{_mm_cell(step.cv_max)}"
            f"{cell(step.cv_whitened_rms, 8, 3)}{cell(step.chi2_dof, 10, 3)}  "
            f"{verdict_word(step.check)}")
