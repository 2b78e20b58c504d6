"""`hostpc fit DATASET`: fit an error model to a saved dataset and print the result."""

from __future__ import annotations

import argparse
import json
import sys

from hostpc.cli.format import format_fit_summary
from hostpc.cli.numbers import CV_FOLDS
from hostpc.dataset import load_dataset
from hostpc.fitting import fit


def register(subparsers: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    parser = subparsers.add_parser(
        "fit",
        help="fit an error model to a dataset file",
        description=(
            "Fit joint zero offsets (and any other effects) to a zerocal dataset. The default "
            "model is joint_offsets plus every frame the dataset does not mark as known."
        ),
    )
    parser.add_argument("dataset", help="dataset file (zerocal-dataset/1 JSON)")
    add_model_options(parser)
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
                        help="Python file defining extra effects (repeatable)")
    parser.add_argument("--loss", choices=("linear", "huber", "cauchy"), default="linear",
                        help="robust loss on whitened residuals (default: linear)")
    parser.add_argument("--cv-folds", type=CV_FOLDS, default=5,
                        help="folds of the cross-validated RMS (0 to skip, else 2..1000; "
                        "default 5)")


def run(args: argparse.Namespace) -> int:
    dataset = load_dataset(args.dataset)
    result = fit(dataset, args.effects, plugins=args.plugin, loss=args.loss,
                 cv_folds=args.cv_folds)
    if args.json:
        json.dump(result.to_dict(), sys.stdout, indent=2, allow_nan=False)
        sys.stdout.write("\n")
    else:
        print(format_fit_summary(result, source=args.dataset))
    return 0
