"""Pre-flight checks of `hostpc calibrate`: everything that can be wrong on the command line
is found before anything connects to the robot or moves it (exit code 2, one line, and no
run folder left behind).

- `--effects` / `--plugin`: every named effect exists (built-in, entry point or plugin file)
  and every plugin file loads;
- `--known`: only frames the method estimates; a frame the method does not have would be
  ignored silently and leave a parameter unidentifiable (e.g. `--known target` with
  sphere_probe, whose reference is the `sphere`: J1 stays unidentifiable);
- `--reference`: the file is a valid cell reference recorded with this method;
- `--out`: a folder (or nothing yet), not a file, and not a folder that holds a run.
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

from hostpc.calibrate.journal import Journal
from hostpc.dataset.kind_registry import kind_descriptor
from hostpc.errors import EffectError, InputError


def check_known_frames(method: str, known: tuple[str, ...] | None,
                       plugins: Iterable[str | Path] = ()) -> None:
    """InputError if `known` names a frame `method` does not estimate (the frames its
    kind's descriptor lists; a kind that lists none accepts any)."""
    if not known:
        return
    kind = kind_descriptor(method, plugins)
    frames = kind.known_frames if kind is not None else None
    if not known or frames is None:
        return
    foreign = [name for name in known if name not in frames]
    if foreign:
        raise InputError(
            f"--known {','.join(known)}: {', '.join(foreign)} is not a {method} frame (its "
            f"frames: {', '.join(frames)}); holding it would leave the model's parameters "
            "unidentifiable")


def check_reference_option(option: str | None, method: str | None) -> None:
    """InputError (one line) if `--reference FILE` is unreadable, malformed or recorded
    with another method (robot model and serial are checked once the controller said
    them, still before anything moves)."""
    if option is None or option == "none":
        return
    from hostpc.calibrate.reference import check_reference_matches, load_reference

    check_reference_matches(load_reference(option), method=str(method), robot_model="",
                            robot_serial=None, where=f"--reference {option}")


def check_model_options(effects: str | None, plugins: tuple[str, ...]) -> None:
    """EffectError if a plugin file does not load or `effects` names an unknown effect."""
    from hostpc.model.registry import available_effects

    registry = available_effects(plugins)
    if effects is None:
        return
    names = [item.strip().lstrip("+-") for item in effects.split(",") if item.strip()]
    if not names:
        raise EffectError(f"--effects {effects!r}: names no effect")
    unknown = [name for name in names if name not in registry]
    if unknown:
        raise EffectError(f"--effects {effects!r}: unknown effect {unknown[0]!r} (known: "
                          f"{', '.join(sorted(registry))})")


def check_out_folder(run_dir: Path) -> None:
    """InputError if `run_dir` is a file, lies under a file, or already holds a run."""
    for path in (run_dir, *run_dir.parents):
        if path.exists() and not path.is_dir():
            raise InputError(f"--out {run_dir}: {path} is a file, not a folder")
    if Journal(run_dir).exists:
        raise InputError(f"--out {run_dir}: already holds a run; continue it with "
                         f"--resume {run_dir} or choose another folder")
