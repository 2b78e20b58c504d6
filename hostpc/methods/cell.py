"""The nominal description of a calibration cell: sensor mount, target, known frames.

Where it comes from, in order (later wins, key by key):
1. the controller's camera description (`RobotState.camera`, what `get_state` reports:
   `T_flange_camera_nominal`, `target.centre_nominal`, `baseline_nominal`, `chessboard`...);
2. a `--cell FILE` JSON document with the same keys or the short ones below;
3. `--known` on the command line.

Cell file (SI units, docs/calibrate.md):

    {"robot": "ur5e",
     "tool": {"xyz": [0.0, -0.06, 0.04], "rpy": [0.0, 0.0, 0.0]},
     "target": {"centre": [0.45, 0.15, 0.0], "normal": [0, 0, 1], "radius": 0.01},
     "known": ["target"],
     "image_width": 1280, "image_height": 1024, "baseline": 0.12,
     "chessboard": {"cols": 9, "rows": 6, "square_size": 0.025, "n_views": 20}}

`tool` is the LEFT camera optical frame in the flange frame (conventions.md), `target` the
target centre in the base frame. Frames not listed in `known` are estimated by the fit.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from hostpc.dataset import FramePose
from hostpc.dataset.kind_registry import kind_descriptors
from hostpc.errors import InputError
from hostpc.input_files import CONFIG, read_input_text
from hostpc.json_object import JsonObject


def frame_names(plugins: Iterable[str | Path] = ()) -> tuple[str, ...]:
    """Frame names `known` may list: every registered kind's frames, and `base` (each
    method uses its own: stereo_target tool, target)."""
    names = {"base": None}
    for kind in kind_descriptors(plugins).values():
        names.update(dict.fromkeys(kind.model.frames))
    return tuple(names)


@dataclass(frozen=True)
class Cell:
    """Nominal cell. tool: T_flange_tool nominal (left camera optical frame, m / rad), or
    None if not described; target: (3,) target centre in base (m) or None;
    target_normal: (3,) unit plate normal in base,
    facing the camera side; target_radius / plate_radius: m; known: frames held fixed;
    image_size: (width, height) px or None; baseline: stereo baseline (m) or None;
    chessboard: {cols, rows, square_size, n_views} for rig calibration, or None;
    raw: the merged description (other methods read their own keys from it)."""

    robot: str
    tool: FramePose | None
    target: np.ndarray | None
    target_normal: np.ndarray
    target_radius: float
    plate_radius: float | None = None
    known: tuple[str, ...] = ()
    image_size: tuple[int, int] | None = None
    baseline: float | None = None
    chessboard: JsonObject | None = None
    raw: JsonObject = field(default_factory=dict)

    def to_dict(self) -> JsonObject:
        """JSON form (the cell file format; SI units)."""
        extra = {k: v for k, v in self.raw.items() if k not in _CELL_KEYS}
        return {
            **extra,
            "robot": self.robot,
            "tool": (None if self.tool is None else
                     {"xyz": self.tool.xyz.tolist(), "rpy": self.tool.rpy.tolist()}),
            "target": None if self.target is None else {
                "centre": self.target.tolist(),
                "normal": self.target_normal.tolist(),
                "radius": self.target_radius,
                "plate_radius": self.plate_radius,
            },
            "known": list(self.known),
            "image_width": self.image_size[0] if self.image_size else None,
            "image_height": self.image_size[1] if self.image_size else None,
            "baseline": self.baseline,
            "chessboard": dict(self.chessboard) if self.chessboard else None,
            **({"probe": dict(self.raw["probe"])} if self.raw.get("probe") else {}),
        }


_CELL_KEYS = frozenset({"robot", "tool", "target", "known", "image_width", "image_height",
                        "baseline", "baseline_nominal", "chessboard",
                        "T_flange_camera_nominal"})


def require_camera_cell(cell: Cell) -> tuple[FramePose, np.ndarray]:
    """(tool, target) of a camera method's cell; InputError if the cell lacks them."""
    if cell.tool is None:
        raise InputError("cell: no camera mount (tool / T_flange_camera_nominal) from the "
                         "controller; give one with --cell FILE")
    if cell.target is None:
        raise InputError("cell: no target (target.centre) from the controller; give one "
                         "with --cell FILE")
    return cell.tool, cell.target


def _merge(base: JsonObject, overrides: JsonObject) -> JsonObject:
    merged = dict(base)
    for key, value in overrides.items():
        if isinstance(value, dict) and isinstance(merged.get(key), dict):
            merged[key] = _merge(merged[key], value)
        else:
            merged[key] = value
    return merged


def load_cell_file(path: str | Path) -> JsonObject:
    """Read a --cell JSON file as a mapping; InputError naming the file if unreadable."""
    path = Path(path)
    try:
        data = json.loads(read_input_text(path, CONFIG, f"--cell {path}"))
    except OSError as exc:
        raise InputError(f"--cell {path}: cannot read ({exc.strerror})") from None
    except ValueError as exc:
        raise InputError(f"--cell {path}: not valid JSON ({exc})") from None
    if not isinstance(data, dict):
        raise InputError(f"--cell {path}: expected a JSON object")
    return data


def parse_known(text: str | None, plugins: Iterable[str | Path] = ()) -> tuple[str, ...] | None:
    """`--known tool,target` / `none` -> names; None if not given. InputError if unknown."""
    if text is None:
        return None
    names = [n.strip() for n in text.split(",") if n.strip()]
    if names in (["none"], []):
        return ()
    known = frame_names(plugins)
    for name in names:
        if name not in known:
            raise InputError(f"--known {text!r}: unknown frame {name!r} "
                             f"(expected {', '.join(known)} or none)")
    return tuple(dict.fromkeys(names))


def _vector(where: str, value: Any, size: int = 3) -> np.ndarray:
    try:
        array = np.asarray(value, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise InputError(f"cell {where}: expected {size} numbers, got {value!r}") from None
    if array.shape != (size,) or not np.all(np.isfinite(array)):
        raise InputError(f"cell {where}: expected {size} finite numbers, got {value!r}")
    return array


def build_cell(
    camera_description: JsonObject,
    robot: str,
    cell_file: JsonObject | None = None,
    known: tuple[str, ...] | None = None,
    default_known: tuple[str, ...] = (),
    plugins: Iterable[str | Path] = (),
) -> Cell:
    """Merge the controller's description, a cell file and --known into a Cell.

    InputError naming the bad key; a missing mount or target leaves it None (a camera
    method checks with `require_camera_cell`).
    """
    raw = _merge(camera_description, cell_file or {})
    tool_spec = raw.get("tool") or raw.get("T_flange_camera_nominal")
    tool = None
    if isinstance(tool_spec, Mapping):
        tool = FramePose(xyz=_vector("tool.xyz", tool_spec.get("xyz")),
                         rpy=_vector("tool.rpy", tool_spec.get("rpy", [0.0, 0.0, 0.0])))
    target_spec = raw.get("target")
    if not isinstance(target_spec, Mapping):
        target_spec = {}
    centre = target_spec.get("centre", target_spec.get("centre_nominal"))
    target = None if centre is None else _vector("target.centre", centre)
    normal = _vector("target.normal", target_spec.get("normal", [0.0, 0.0, 1.0]))
    if np.linalg.norm(normal) < 1e-9:
        raise InputError("cell target.normal: must be non-zero")
    radius = float(target_spec.get("radius", 0.01))
    if not (math.isfinite(radius) and radius > 0):
        raise InputError(f"cell target.radius: must be positive, got {radius!r}")
    plate = target_spec.get("plate_radius")
    width, height = raw.get("image_width"), raw.get("image_height")
    baseline = raw.get("baseline", raw.get("baseline_nominal"))
    board = raw.get("chessboard")
    if known is None:
        listed = raw.get("known")
        known = tuple(listed) if isinstance(listed, list) else default_known
    for name in known:
        if name not in frame_names(plugins):
            raise InputError(f"cell known: unknown frame {name!r}")
    return Cell(
        robot=str(raw.get("robot") or robot),
        tool=tool,
        target=target,
        target_normal=normal / np.linalg.norm(normal),
        target_radius=radius,
        plate_radius=float(plate) if plate is not None else None,
        known=tuple(known),
        image_size=(int(width), int(height)) if width and height else None,
        baseline=float(baseline) if baseline else None,
        chessboard=dict(board) if isinstance(board, Mapping) else None,
        raw=raw,
    )


def cell_from_dict(data: JsonObject, plugins: Iterable[str | Path] = ()) -> Cell:
    """Rebuild a Cell from `Cell.to_dict()` (the run folder's copy)."""
    return build_cell({}, str(data.get("robot", "")), data, tuple(data.get("known", ())),
                      plugins=plugins)
