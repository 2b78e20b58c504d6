"""`hostpc diagnose DATASET`: is the model adequate, where does it fail, what is missing."""

from __future__ import annotations

import argparse
import json
import sys
from typing import TYPE_CHECKING

from hostpc.cli.fit import add_model_options
from hostpc.diagnostics.advice import mm
from hostpc.errors import InputError

if TYPE_CHECKING:
    from hostpc.diagnostics import Diagnosis

TOP_INTERACTIONS = 10


def register(subparsers: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    parser = subparsers.add_parser(
        "diagnose",
        help="compare the model with the measurements and find the missing effect",
        description=(
            "Fit the model to a dataset, judge whether it is adequate (chi-square against its "
            "band, held-out RMS), show where it fails (residuals against every recorded "
            "variable), rank the effects that could be missing, and search for any parameter "
            "that varies with any variable. See docs/diagnostics.md."
        ),
    )
    parser.add_argument("dataset", help="dataset file (zerocal-dataset/1 JSON)")
    add_model_options(parser)
    parser.add_argument("--ladder", action="store_true",
                        help="fit the nested models, adding the best candidate while it is "
                        "significant, and show each step")
    parser.add_argument("--candidates", metavar="LIST",
                        help="comma-separated effects to try (default: every effect that "
                        "applies)")
    parser.add_argument("--alpha", type=float, default=None,
                        help="family-wise significance of each family of tests "
                        "(default 0.001)")
    parser.add_argument("--json", action="store_true", help="print one JSON document")
    parser.add_argument("--report", metavar="FILE.html",
                        help="also write a self-contained HTML report")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from hostpc.diagnostics import DEFAULT_ALPHA, diagnose

    if args.cv_folds < 0:
        raise InputError(f"--cv-folds {args.cv_folds}: must not be negative")
    candidates = None
    if args.candidates:
        candidates = [c.strip() for c in args.candidates.split(",") if c.strip()]
    diagnosis = diagnose(
        args.dataset, args.effects, plugins=args.plugin, ladder=args.ladder,
        candidates=candidates, alpha=DEFAULT_ALPHA if args.alpha is None else args.alpha,
        cv_folds=args.cv_folds, loss=args.loss,
    )
    if args.report:
        from hostpc.report import write_report

        write_report(args.report, diagnosis)
    if args.json:
        json.dump(diagnosis.to_dict(), sys.stdout, indent=2, allow_nan=False)
        sys.stdout.write("\n")
    else:
        print(format_diagnosis(diagnosis))
        if args.report:
            print(f"\nreport written to {args.report}")
    return 0


def _p(value: float) -> str:
    return f"{value:.2g}"


def _sigma(value: float | None) -> str:
    return "-" if value is None else f"{value:.3f}"


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
        f"verdict: {'adequate' if a.adequate else 'NOT adequate'}",
        f"  chi2/dof {a.chi2_dof:.3f} (band {a.chi2_band[0]:.3f}..{a.chi2_band[1]:.3f} for "
        f"{a.dof} dof, p = {_p(a.p_value)})",
        f"  in-sample RMS {mm(a.rms)}, max {mm(a.max)}",
    ]
    if a.cv_rms is not None:
        lines.append(f"  held-out ({a.cv_folds}-fold) RMS {mm(a.cv_rms)}, max {mm(a.cv_max)}, "
                     f"whitened {_sigma(a.cv_whitened_rms)} sigma (1 = the stated noise)")
    lines.append(f"  noise {mm(a.noise_rms)} per sample, corrected for the fitted parameters "
                 f"(the stated covariances predict {mm(a.expected_noise_rms)})")
    for reason in a.reasons:
        lines.append(f"  - {reason}")
    worst = ", ".join(f"#{w.index} {w.whitened_norm:.2f} sigma ({mm(w.norm)})"
                      for w in diagnosis.residuals.worst[:5])
    lines += ["", f"worst samples: {worst}", "",
              "residuals binned against each variable (* significant):"]
    for pattern in diagnosis.residuals.patterns:
        mark = "*" if pattern.significant else " "
        lines.append(f"  {mark} {pattern.variable:<14} chi2 {pattern.chi2:8.1f} / {pattern.dof:<3} "
                     f"p = {_p(pattern.p_value)}")
    lines += ["", "candidate effects (best first; * significant):",
              f"    {'effect':<24}{'dBIC':>9}{'dBIC all':>10}{'RMS mm':>10}{'held-out':>10}"
              f"{'chi2/dof':>10}{'p':>10}"]
    for c in check.candidates:
        mark = "*" if c.significant else " "
        held = "-" if c.cv_rms is None else f"{c.cv_rms * 1e3:.4f}"
        lines.append(f"  {mark} {c.effect:<24}{c.delta_bic:9.1f}{c.delta_bic_full:10.1f}"
                     f"{c.rms * 1e3:10.4f}{held:>10}{c.chi2_dof:10.3f}{_p(c.p_value):>10}")
    for s in check.skipped:
        lines.append(f"    {s.effect:<24}skipped: {s.reason}")
    lines += ["", f"parameter varies with variable (top {TOP_INTERACTIONS} of "
              f"{check.n_interaction_tests}; * significant):"]
    for i in check.interactions[:TOP_INTERACTIONS]:
        mark = "*" if i.significant else " "
        lines.append(f"  {mark} {i.sentence:<44} score {i.score:6.1f}  p = {_p(i.p_value)}")
    if diagnosis.ladder:
        lines += ["", "ladder:",
                  f"  {'step':<5}{'added':<24}{'RMS mm':>10}{'held-out':>10}{'max':>10}"
                  f"{'sigma':>8}{'chi2/dof':>10}  verdict"]
        for step in diagnosis.ladder:
            held = "-" if step.cv_rms is None else f"{step.cv_rms * 1e3:.4f}"
            worst_held = "-" if step.cv_max is None else f"{step.cv_max * 1e3:.4f}"
            lines.append(f"  {step.step:<5}{step.added or '(current model)':<24}"
                         f"{step.rms * 1e3:10.4f}{held:>10}{worst_held:>10}"
                         f"{_sigma(step.cv_whitened_rms):>8}{step.chi2_dof:10.3f}  "
                         f"{'adequate' if step.adequate else 'NOT adequate'}")
    lines += ["", "advice:"] + [f"  - {sentence}" for sentence in diagnosis.advice]
    return "\n".join(lines)
