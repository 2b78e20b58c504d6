"""`hostpc stereo-calibrate`: calibrate the stereo rig from chessboard image pairs on disk.

    hostpc stereo-calibrate --images DIR --board COLSxROWS --square M --out rig.json
                            [--accept-poor] [--json]

DIR holds `left_<id>.png` / `right_<id>.png` pairs (also .bmp, .tif, .jpg), paired by
`<id>`; COLSxROWS counts INNER corners (e.g. 9x6); M is the square side in metres. Prints
the RMS, both cameras' intrinsics, the baseline and any warnings. A poor calibration (RMS
> 0.5 px, fewer than 8 usable views, poor coverage, ...) is not saved and exits with code 2
unless --accept-poor is given. The rig file is what `--rig FILE` of the other commands reads.
"""

from __future__ import annotations

import argparse
import json
import math
import re
from pathlib import Path
from typing import Any

import numpy as np

from hostpc.errors import InputError
from hostpc.json_object import JsonObject
from hostpc.vision.rig import save_rig
from hostpc.vision.rig_calibration import (
    ChessboardSpec,
    RigCalibration,
    calibrate_rig,
    load_image_pairs,
)


def register(subparsers: Any) -> None:
    """Add the `stereo-calibrate` subcommand."""
    parser = subparsers.add_parser(
        "stereo-calibrate",
        help="calibrate the stereo rig from chessboard image pairs",
        description="Calibrate both cameras and their relative pose from chessboard image "
        "pairs (left_<id>.png / right_<id>.png) and save the rig as JSON.",
    )
    parser.add_argument("--images", required=True, metavar="DIR", help="folder of image pairs")
    parser.add_argument(
        "--board", required=True, metavar="COLSxROWS", help="inner corners, e.g. 9x6"
    )
    parser.add_argument("--square", required=True, metavar="M", help="square side (m)")
    parser.add_argument("--out", required=True, metavar="FILE", help="rig JSON file to write")
    parser.add_argument(
        "--accept-poor", action="store_true", help="save a calibration flagged as poor"
    )
    parser.add_argument("--json", action="store_true", help="print JSON instead of text")
    parser.set_defaults(func=run)


def parse_board(board: str, square: str) -> ChessboardSpec:
    """`COLSxROWS` and a square size (m) -> ChessboardSpec; InputError naming the option."""
    match = re.fullmatch(r"\s*(\d+)\s*[xX]\s*(\d+)\s*", board)
    if not match:
        raise InputError(f"--board {board!r}: expected COLSxROWS inner corners, e.g. 9x6")
    try:
        size = float(square)
    except ValueError:
        raise InputError(f"--square {square!r}: not a number (metres)") from None
    if not (math.isfinite(size) and 0.0 < size < 1.0):
        raise InputError(f"--square {square!r}: expected a side in metres, 0 < M < 1")
    try:
        return ChessboardSpec(int(match.group(1)), int(match.group(2)), size)
    except ValueError as exc:
        raise InputError(f"--board {board!r}: {exc}") from None


def summary(calibration: RigCalibration, ids: list[str]) -> JsonObject:
    """`--json`: the calibration (pixels, metres); view ids from the file names."""
    rig = calibration.rig
    return {
        "ok": calibration.ok,
        "rms_px": calibration.rms,
        "views_used": [ids[k] for k in calibration.used_views],
        "views_skipped": {ids[k]: reason for k, reason in calibration.skipped_views},
        "per_view_rms_px": dict(
            zip([ids[k] for k in calibration.used_views], calibration.per_view_rms, strict=True)
        ),
        "image_size": list(rig.image_size),
        "left": _camera_json(rig.K_left, rig.dist_left),
        "right": _camera_json(rig.K_right, rig.dist_right),
        "baseline_m": rig.baseline,
        "T": rig.T.tolist(),
        "warnings": list(calibration.warnings),
    }


def _camera_json(K: np.ndarray, dist: np.ndarray) -> JsonObject:
    """One camera's intrinsics (px) and distortion coefficients in `summary`."""
    return {"fx": float(K[0, 0]), "fy": float(K[1, 1]), "cx": float(K[0, 2]),
            "cy": float(K[1, 2]), "distortion": [float(v) for v in dist]}


def _print_text(calibration: RigCalibration, ids: list[str], out: Path | None) -> None:
    rig = calibration.rig
    print(f"stereo rig: {len(calibration.used_views)} views used, "
          f"{len(calibration.skipped_views)} skipped, image {rig.image_size[0]}x"
          f"{rig.image_size[1]}")
    print(f"  RMS reprojection error: {calibration.rms:.3f} px")
    for side, K, distortion in (("left", rig.K_left, rig.dist_left),
                                ("right", rig.K_right, rig.dist_right)):
        dist = " ".join(f"{float(v):+.5f}" for v in distortion)
        print(f"  {side:5s} fx {float(K[0, 0]):.2f}  fy {float(K[1, 1]):.2f}  "
              f"cx {float(K[0, 2]):.2f}  cy {float(K[1, 2]):.2f} px   distortion {dist}")
    print(f"  baseline: {1e3 * rig.baseline:.3f} mm")
    for k, reason in calibration.skipped_views:
        print(f"  skipped view {ids[k]}: {reason}")
    for warning in calibration.warnings:
        print(f"  WARNING: {warning}")
    if out is not None:
        print(f"  saved: {out}")


def run(args: argparse.Namespace) -> int:
    """Calibrate, print, save (unless poor and not --accept-poor). Returns the exit code."""
    board = parse_board(args.board, args.square)
    loaded = load_image_pairs(args.images)
    ids = [key for key, _, _ in loaded]
    calibration = calibrate_rig([(left, right) for _, left, right in loaded], board)
    save = calibration.ok or args.accept_poor
    out = Path(args.out)
    if save:
        save_rig(calibration.rig, out)
    if args.json:
        print(json.dumps({**summary(calibration, ids), "saved": str(out) if save else None},
                         indent=2))
    else:
        _print_text(calibration, ids, out if save else None)
    if not save:
        raise InputError(
            f"poor calibration not saved ({'; '.join(calibration.warnings)}); "
            "rerun with --accept-poor to save it anyway"
        )
    return 0
