"""`hostpc fit DATASET`: fit an error model to a saved dataset and print the result."""

from __future__ import annotations

import argparse
import json
import sys

from hostpc.cli.archive_options import add_archive_options, dataset_from_archive
from hostpc.cli.format import format_fit_summary, model_adequacy
from hostpc.cli.numbers import CV_FOLDS
from hostpc.cli.robots import add_robot_override, load_dataset_with_robot, robot_document
from hostpc.dataset import load_dataset
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
    parser.add_argument("dataset", nargs="?",
                        help="dataset file (zerocal-dataset/1 JSON); or --db URL --run ID")
    add_model_options(parser)
    add_constraint_options(parser)
    add_archive_options(parser, read=True)
    add_robot_override(parser)
    parser.add_argument("--json", action="store_true", help="print one JSON document")
    parser.set_defaults(func=run)


def add_model_options(parser: argparse.ArgumentParser) -> None:
    """--effects, --plugin, --loss, --cv-folds: shared with diagnose and calibrate."""
    parser.add_argument(
        "--effects",
        help="comma-separated effects (e.g. joint_offsets,tool,target); '+name' adds to the "
        "default model, '-name' removes from it",
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
                        "(e.g. tool.x=0.045+-0.0005m, joint_offsets.q1=0+-0.01deg); "
                        "repeatable")
    parser.add_argument("--hold", action="append", default=[], metavar="NAME[,NAME...]",
                        help="parameters kept at their nominal value by the fit")


def run(args: argparse.Namespace) -> int:
    if args.db or args.run is not None:
        if args.dataset:
            raise InputError("give a dataset file or --db URL --run ID, not both")
        if not args.db:
            raise InputError("--run needs --db URL")
        args.dataset = dataset_from_archive(args)
    elif not args.dataset:
        raise InputError("a dataset file is required (or --db URL --run ID)")
    robot = robot_document(args)
    dataset = (load_dataset(args.dataset, plugins=args.plugin) if robot is None
               else load_dataset_with_robot(args.dataset, robot, plugins=args.plugin))
    dataset = with_constraints(dataset, args.prior, args.hold)
    result = fit(dataset, args.effects, plugins=args.plugin, loss=args.loss,
                 cv_folds=args.cv_folds)
    if args.json:
        document = result.to_dict()
        document["model_adequacy"] = model_adequacy(result, args.dataset)
        json.dump(document, sys.stdout, indent=2, allow_nan=False)
        sys.stdout.write("\n")
    else:
        print(format_fit_summary(result, source=args.dataset))
    return 0
