"""`hostpc fit DATASET`: fit an error model to a saved dataset and print the result."""

from __future__ import annotations

import argparse
import json
import math
import sys

from hostpc.cli.format import (
    UNITS_HINT_NOISE_RATIO,
    below_band,
    format_fit_summary,
    model_adequacy,
)
from hostpc.cli.numbers import CV_FOLDS
from hostpc.cli.robot_options import add_robot_override, data_options
from hostpc.errors import InputError
from hostpc.fitting import fit
from hostpc.fitting.priors import with_constraints


def register(subparsers: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    parser = subparsers.add_parser(
        "fit",
        help="fit an error model to a dataset file",
        description=(
            "Fit joint zero offsets (and any other effects) to a zerocal dataset. The default "
            "model is joint_offsets plus every frame the dataset does not mark as known."
        ),
    )
    # fit's own options (an archive, a URDF to write): imported here, not by diagnose
    from hostpc.cli.archive_options import add_archive_options
    from hostpc.cli.urdf_out import add_write_urdf_option

    parser.add_argument("dataset", nargs="?",
                        help="dataset file (zerocal-dataset/1 JSON); or --db URL --run ID")
    add_model_options(parser)
    add_constraint_options(parser)
    add_archive_options(parser, read=True)
    add_robot_override(parser)
    add_write_urdf_option(parser)
    parser.add_argument("--json", action="store_true", help="print one JSON document")
    parser.add_argument("--jackknife", action="store_true",
                        help="also the leave-one-pose-out jackknife sigma of every parameter "
                        "(one linearised refit per pose; no noise model assumed)")
    parser.set_defaults(func=run)


def add_model_options(parser: argparse.ArgumentParser) -> None:
    """--effects, --plugin, --loss, --cv-folds: shared with diagnose and calibrate."""
    parser.add_argument(
        "--effects",
        help="comma-separated effects (e.g. joint_offsets,tool,target); '+name' adds to the "
        "default model, '-name' removes from it; 'auto': the model (nominal, offsets, "
        "offsets + geometry, the diagnosis ladder's) with the best pose-grouped held-out "
        "error, one-standard-error rule toward the simpler",
    )
    parser.add_argument("--plugin", action="append", default=[], metavar="FILE",
                        help="Python file defining extra effects or measurement models "
                        "(repeatable)")
    parser.add_argument("--loss", choices=("linear", "huber", "cauchy"), default="linear",
                        help="robust loss on whitened residuals (default: linear)")
    parser.add_argument("--cv-folds", type=CV_FOLDS, default=5,
                        help="folds of the cross-validated RMS (0 to skip, else 2..1000; "
                        "default 5)")


def add_constraint_options(parser: argparse.ArgumentParser) -> None:
    """--prior, --hold: shared with diagnose (hostpc.fitting.priors)."""
    parser.add_argument("--prior", action="append", default=[], metavar="NAME=VALUE+-SIGMA",
                        help="a parameter known to within a tolerance, units as printed "
                        "(e.g. tool.x=0.045+-0.0005m, joint_offsets.q1=0+-0.01deg; a "
                        "prismatic joint's offset is a length: =0+-0.1mm); repeatable")
    parser.add_argument("--hold", action="append", default=[], metavar="NAME[,NAME...]",
                        help="parameters kept at their nominal value by the fit")


def run(args: argparse.Namespace) -> int:
    from hostpc.cli.archive_options import dataset_from_archive
    from hostpc.cli.urdf_out import check_urdf_robot, write_calibrated_urdf
    from hostpc.fitting.resampling import jackknife_std, scaled_std

    if args.db or args.run is not None:
        if args.dataset:
            raise InputError("give a dataset file or --db URL --run ID, not both")
        if not args.db:
            raise InputError("--run needs --db URL")
        args.dataset = dataset_from_archive(args)
    elif not args.dataset:
        raise InputError("a dataset file is required (or --db URL --run ID)")
    from hostpc.cli.robots import load_dataset_as_asked  # reads robots: only to fit

    dataset = with_constraints(load_dataset_as_asked(args.dataset, args), args.prior,
                               args.hold)
    options = data_options(args)  # carried into every next command
    if args.write_urdf:
        check_urdf_robot(dataset.robot, args.write_urdf, args.dataset)
    choice = None
    parts = [part.strip() for part in (args.effects or "").split(",")]
    if "auto" in parts and len(parts) > 1:
        raise InputError(f"--effects {args.effects}: 'auto' chooses the whole model and takes "
                         "no other effects; give --effects auto alone, or list the effects")
    if args.effects == "auto":
        from hostpc.diagnostics.model_choice import choose_model

        choice = choose_model(dataset, plugins=args.plugin, cv_folds=args.cv_folds or 5,
                              loss=args.loss)
        result = choice.fit
    else:
        result = fit(dataset, args.effects, plugins=args.plugin, loss=args.loss,
                     cv_folds=args.cv_folds)
    adequacy = model_adequacy(result, args.dataset, options)  # chi2/dof vs its band, once
    # outside the band (above: the noise is understated or an effect is missing; below: the
    # stated noise is pessimistic): the sigmas scaled by sqrt(chi2/dof) beside the stated
    scaled = (scaled_std(result) if adequacy.explains_data is False
              or below_band(result.chi2_dof, result.dof) else None)
    jackknife = jackknife_std(result) if args.jackknife else None
    if args.json:
        document = result.to_dict()
        if choice is not None:
            document["model_choice"] = {
                "chosen": choice.chosen, "folds": choice.folds,
                "rule": "fewest free parameters within one standard error of the best "
                        "pose-grouped held-out score",
                "models": [{"name": m.name, "effects": list(m.effects),
                            "free_parameters": m.free_parameters, "converged": m.converged,
                            "held_out_score": m.score, "standard_error": m.standard_error,
                            "cv_rms": m.cv_rms, "note": m.note or None}
                           for m in choice.scores],
                "outliers": choice.outlier_note or None,
                "scored_without": [] if choice.kept is None else list(choice.kept.left_out)}
        document["noise_scale"] = (math.sqrt(result.chi2_dof)
                                   if math.isfinite(result.chi2_dof) else None)
        for column, values in (("std_scaled", scaled), ("std_jackknife", jackknife)):
            if values is not None:
                for k, entry in enumerate(document["parameters"].values()):
                    entry[column] = float(values[k]) if math.isfinite(values[k]) else None
        document["model_adequacy"] = adequacy.to_json()
        from hostpc.calibrate.measured_under import measured_under_field

        document.update(measured_under_field(args.dataset))  # a run folder's: for push
        sys.stdout.write(json.dumps(document, indent=2, allow_nan=False))
        sys.stdout.write("\n")
    else:
        if choice is not None:
            print(f"model chosen by pose-grouped held-out error ({choice.folds} folds; the "
                  "fewest free parameters within one standard error of the best):")
            print("\n".join(choice.table()))
            if choice.outlier_note:
                print(f"outliers: {choice.outlier_note}")
            print()
        from hostpc.cli.units_hint import (
            declared_angle_unit,
            declared_length_unit,
            length_unit_hint,
        )

        # only where the summary says it (residuals 100 times the stated noise): the hint
        # registers the robot onto the points
        hint = (length_unit_hint(dataset, declared_length_unit(args.dataset),
                                 result.problem.context.chain, declared_angle_unit(args.dataset))
                if math.sqrt(max(result.chi2_dof, 0.0)) >= UNITS_HINT_NOISE_RATIO else "")
        print(format_fit_summary(result, source=args.dataset, scaled=scaled,
                                 jackknife=jackknife, options=options, units_hint=hint))
    if args.write_urdf:
        write_calibrated_urdf(result, args.write_urdf, args.dataset + options, args.json)
    return 0

