"""`hostpc predict FIT.json DATASET`: how well a saved fit predicts data it never saw.

    hostpc fit day1.json --effects +geometry --json > fit.json
    hostpc predict fit.json day2.json [--refit-frames] [--json] [--plugin FILE]

Every sample of DATASET is predicted by the fit's model at the fit's values and compared
with its measurement: the position error (RMS, max, mm), the orientation error where it is
measured (deg) and the whitened RMS (1 = at the stated noise). By default the instrument's
frames are the fit's, as fitted (absolute, from FIT.json), not DATASET's own (an import
estimates those from the very file it reads). With --refit-frames the instrument's frames
(a tracker registered anew, a target moved between days) are estimated on DATASET with
the robot's parameters held at the fit's values, so the error that remains is the robot
model's. The output says which frames were used. The fit and DATASET must be the same
robot (the fit records its robot's name and kinematics fingerprint; `--robot` reads
DATASET with another robot, as `hostpc fit --robot` does); a fit with a plugin effect
predicts with the same `--plugin FILE` it was fitted with. Any fit predicts, with or without
joint offsets (`--effects auto` may choose the nominal model). Exit 0; 2 for a bad file,
another robot or a model that does not match.
"""

from __future__ import annotations

import argparse
import json
import math
from typing import Any

from hostpc.calibrate.offline_push import SavedFit, load_saved_fit
from hostpc.cli.robot_options import add_robot_override, data_options
from hostpc.dataset import Dataset
from hostpc.dataset.writing import frames_from_json
from hostpc.errors import EffectError, InputError
from hostpc.fitting.prediction import FittedModel, predict
from hostpc.model.context import robot_identity


def register(subparsers: Any) -> None:
    """Add the `predict` subcommand."""
    parser = subparsers.add_parser(
        "predict",
        help="predict a dataset the fit never saw with a saved fit (hostpc fit --json)",
        description="Predict every sample of DATASET with the model and values of FIT.json "
        "and report the error: the held-out test on a second day of data.",
    )
    parser.add_argument("fit", metavar="FIT.json", help="output of `hostpc fit DATASET --json`")
    parser.add_argument("dataset", metavar="DATASET", help="zerocal-dataset/1 file to predict")
    parser.add_argument("--refit-frames", action="store_true",
                        help="estimate the instrument's frames on DATASET, the robot's "
                        "parameters held at the fit's values")
    parser.add_argument("--json", action="store_true",
                        help="one JSON document with every sample's prediction")
    parser.add_argument("--plugin", action="append", default=[], metavar="FILE",
                        help="Python file defining the fit's plugin effects or measurement "
                        "model, as given to `hostpc fit --plugin` (repeatable)")
    add_robot_override(parser)
    parser.set_defaults(func=run)


def check_same_robot(saved: SavedFit, dataset: Dataset, fit_path: str, dataset_path: str
                     ) -> None:
    """A fit predicts only the robot it was fitted on: its recorded identity (name and
    kinematics fingerprint, hostpc.model.context.robot_identity) must be the dataset's; a
    fit made before fits recorded it is compared by its built-in robot name, if it has one.
    InputError (one line, exit 2) with the command that fits the dataset's robot."""
    identity = robot_identity(dataset)
    recorded = saved.robot_identity
    if recorded is not None:
        same = recorded["kinematics"] == identity["kinematics"]
        theirs = f"{recorded['name']} (kinematics {recorded['kinematics']})"
    else:
        same = not saved.robot or dataset.robot.name in (None, saved.robot)
        theirs = saved.robot
    if not same:
        raise InputError(
            f"{fit_path} is a fit of robot {theirs}, {dataset_path} is robot "
            f"{identity['name']} (kinematics {identity['kinematics']}): a fit predicts only "
            f"the robot it was fitted on; fit this one instead: hostpc fit {dataset_path} "
            "--json > FIT2.json")


def run(args: argparse.Namespace) -> int:
    from hostpc.cli.robots import load_dataset_as_asked  # reads robots: only to predict

    saved = load_saved_fit(args.fit, offsets=False)
    dataset = load_dataset_as_asked(args.dataset, args)
    check_same_robot(saved, dataset, args.fit, args.dataset)
    frames = None
    if saved.frames is not None:
        try:
            frames = frames_from_json(saved.frames, dataset.frames)
        except ValueError as exc:
            raise InputError(f"{args.fit}: {exc}") from None
    model = FittedModel(saved.effects, dict(zip(saved.names, map(float, saved.x),
                                                strict=True)), frames)
    try:
        prediction = predict(model, dataset, refit_frames=args.refit_frames,
                             plugins=args.plugin)
    except EffectError as exc:  # an effect of the fit that no built-in or plugin defines
        raise InputError(f"{args.fit}: {str(exc).split(';')[0]}: give the plugin file the fit "
                         f"was fitted with: hostpc predict {args.fit} {args.dataset} "
                         "--plugin FILE") from None
    if args.json:
        print(json.dumps({"fit": args.fit, "dataset": args.dataset,
                          "frames": "refitted" if args.refit_frames else "fit",
                          **_finite(prediction.to_dict())}, indent=2))
        return 0
    angle = prediction.angle_rms
    print(f"predicted {dataset.n_samples} samples of {args.dataset} with {args.fit} "
          f"({', '.join(saved.effects)}):")
    print(f"  position error RMS {prediction.rms * 1e3:.4f} mm, max "
          f"{prediction.max * 1e3:.4f} mm"
          + (f"; orientation RMS {math.degrees(angle):.4f} deg" if angle is not None else ""))
    print(f"  whitened RMS {prediction.whitened_rms:.3f} (1 = the dataset's stated noise)")
    if args.refit_frames:
        print("  frames: estimated on this dataset (--refit-frames), the robot held at the "
              f"fit's values: {', '.join(prediction.refitted) or 'none to estimate'}")
    else:
        print(f"  frames: the fit's, as fitted (from {args.fit}); if the instrument was set "
              f"up anew: hostpc predict {args.fit} {args.dataset} --refit-frames"
              f"{data_options(args)}")
    return 0


def _finite(value: Any) -> Any:
    """The document with non-finite numbers as null (strict JSON)."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_finite(v) for v in value]
    return value
