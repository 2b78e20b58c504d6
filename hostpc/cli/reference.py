"""`hostpc reference`: record a cell reference from a good run, and show one.

    hostpc reference record --run RUN --out cell_ref.json [--robot-serial SN] [--force]
    hostpc reference show cell_ref.json

`record` reads a finished run folder (result.json, dataset.json, run.json), refits its
dataset with the run's model and writes every frame the fit estimated, with its covariance
block, tied to the robot (model, serial), the method and the cell
(hostpc.calibrate.reference, format zerocal-cell-reference/1). It refuses a run whose
verification did not PASS (its zeros are not known good), whose fit did not converge, or
whose own reference check found a moved frame; `--force` records anyway (commissioning
with zeros known good by other means). It refuses, even with `--force`, a run that declared
a joint swapped (`--swapped`) and did not calibrate it: that zero is unknown, and the frames
the run estimated carry its error. Whatever J1 / J6 zeros the controller had in that
run are declared good: record right after a verified calibration, or at commissioning.
Later runs load it with `hostpc calibrate --reference cell_ref.json` (docs/calibrate.md).

Exit codes: 0 written / shown; 2 bad input (no run, a run that cannot be a reference, a
malformed reference file, a result.json that is not what the run wrote: read strictly,
hostpc.calibrate.run_result.read_run_result).
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Sequence
from pathlib import Path

from hostpc.calibrate.run_result import RunResult, read_run_result
from hostpc.errors import InputError


def register(subparsers: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    parser = subparsers.add_parser(
        "reference",
        help="record a cell reference from a verified run, or show one",
        description=("A cell reference holds the cell's frames (target, camera mount, "
                     "sphere, tracker registration, reflector nests) with their covariance, "
                     "recorded while the robot's zeros are good; `hostpc calibrate "
                     "--reference FILE` then calibrates every joint and checks the frames. "
                     "See docs/calibrate.md."))
    actions = parser.add_subparsers(dest="action", required=True, metavar="{record,show}")
    record = actions.add_parser("record", help="write a reference from a finished run")
    record.add_argument("--run", required=True, metavar="RUN",
                        help="run folder of `hostpc calibrate` whose zeros are good")
    record.add_argument("--out", required=True, metavar="FILE", help="reference file to write")
    record.add_argument("--robot-serial", metavar="SERIAL",
                        help="the robot's serial (default: the run's --robot-serial, else "
                        "none: later runs then check model and method only)")
    record.add_argument("--force", action="store_true",
                        help="record from a run whose verification did not PASS")
    record.set_defaults(func=run_record)
    show = actions.add_parser("show", help="print a reference file")
    show.add_argument("file", help="a zerocal-cell-reference/1 file")
    show.set_defaults(func=run_show)


def _refusal(run: Path, result: RunResult, swapped: Sequence[int], force: bool
             ) -> tuple[str, str] | None:
    """(why this run cannot be a reference, the next command), None: it can. swapped: the
    joints the run header (run.json) says were declared swapped."""
    calibrate = f"calibrate and verify first: hostpc calibrate --resume {run} --push"
    unknown = _unknown_swapped_zeros(result, swapped)
    if unknown:  # even with --force: the frames the run estimated carry the swapped zero
        names = ", ".join(f"J{n}" for n in unknown)
        outcome = result.outcome or {}
        stored = str(outcome.get("next_command") or "")
        # written knowing these zeros unknown (outcome.unknown_zeros), the stored command
        # proposes no reference from this run; an older run's (no unknown_zeros) may
        recorded = outcome.get("unknown_zeros")
        knowing = isinstance(recorded, list) and set(unknown) <= set(recorded)
        honest = stored if stored and knowing else (
            "hostpc calibrate ... --reference REFERENCE_FROM_BEFORE_THE_SWAP.json, or "
            f"--known FRAME with that frame surveyed, or set {names} with the robot maker's "
            "zeroing procedure")
        return (f"{names} was declared swapped (--swapped) and this run did not calibrate "
                "it: its zero is unknown, so the frames the run estimated carry its error",
                f"next: {honest}")
    reason = _verdict_refusal(result, force)
    return (reason, calibrate) if reason else None


def _unknown_swapped_zeros(result: RunResult, swapped: Sequence[int]) -> tuple[int, ...]:
    """The joints the run declared swapped (`swapped`, from run.json) and did not
    calibrate (outcome.py)."""
    from hostpc.calibrate.outcome import sources_from_outcome, unknown_swapped_zeros

    return unknown_swapped_zeros(sources_from_outcome(result.outcome or {}), swapped)


def _verdict_refusal(result: RunResult, force: bool) -> str | None:
    """Why the run's fit or verification cannot make it a reference (None: they can)."""
    if not result.fit.get("converged"):
        return "its fit did not converge"
    check = result.reference_check or {}
    if check.get("moved"):
        return f"its own reference check found a moved frame ({check.get('likely_cause')})"
    verdict = (result.verify or {}).get("verdict")
    if verdict != "PASS" and not force:
        return (f"its verification is {verdict or 'missing'}, not PASS (its zeros are not "
                "known good); verify first, or record anyway with --force")
    return None


def run_record(args: argparse.Namespace) -> int:
    import hostpc
    from hostpc.calibrate.journal import Journal
    from hostpc.calibrate.outcome import reference_zeros
    from hostpc.calibrate.reference import reference_from_fit
    from hostpc.calibrate.run_header import read_run_header
    from hostpc.dataset import load_dataset
    from hostpc.files import write_json_atomic
    from hostpc.fitting import fit

    run = Path(args.run)
    if not run.is_dir():
        raise InputError(f"--run {run}: not a run folder")
    result = read_run_result(run / "result.json")  # strictly: decisions depend on it
    header = read_run_header(Journal(run))  # its swaps: run.json is the run's record
    refused = _refusal(run, result, header.settings.swapped, args.force)
    if refused:
        raise InputError(f"--run {run}: cannot be a reference: {refused[0]}; {refused[1]}")
    settings = header.settings
    dataset = load_dataset(run / "dataset.json")
    fitted = fit(dataset, _fitted_effects(result) or settings.effects,
                 plugins=settings.plugins, loss=settings.loss, cv_folds=0)
    serial = args.robot_serial or header.robot_serial or ""
    reference = reference_from_fit(fitted, robot_serial=str(serial),
                                   cell=header.cell, source_run=str(run.resolve()),
                                   software=f"zerocal {hostpc.__version__}",
                                   zeros=reference_zeros(result.outcome or {},
                                                         result.plan.get("joints")))
    out = Path(args.out)
    if out.exists() and out.is_dir():
        raise InputError(f"--out {out}: is a folder")
    write_json_atomic(out, reference.to_dict())
    rig = ""
    if reference.rig is not None:  # the camera frame holds for this rig only
        rig_file = out.with_suffix(".rig.json")
        write_json_atomic(rig_file, dict(reference.rig))
        rig = f" --rig {rig_file}"
    print(f"recorded {', '.join(f.name for f in reference.frames)} of {run} "
          f"({reference.method} on {reference.robot_model}"
          f"{', serial ' + reference.robot_serial if reference.robot_serial else ''}) "
          f"in {out}; use it with: hostpc calibrate --reference {out}{rig} ...")
    print(reference.distances_line())
    for line in _zeros_taken_as_good(result, run):
        print(line)
    return 0


def _fitted_effects(result: RunResult) -> list[str] | None:
    """The effects the run's own fit used (result.json ``fit.effects``), None if it names
    none. Not the run's --effects: without one the method's default model applied
    (sphere_probe's + trigger_latency), and a refit without it biases the frames."""
    effects = result.fit.get("effects")
    if isinstance(effects, list) and effects and all(isinstance(e, str) for e in effects):
        return list(effects)
    return None


def _zeros_taken_as_good(result: RunResult, run: Path) -> list[str]:
    """A line per joint the recording run (the folder `run`, as --run named it) did not
    calibrate: the reference fixes the frame that joint trades against, so that joint's
    present zero is taken as good for good."""
    joints = (result.outcome or {}).get("joints") or []
    zeros = {row.joint: row.new_deg for row in result.offsets}
    lines = []
    for joint in joints:
        if not isinstance(joint, dict) or joint.get("status") == "calibrated":
            continue
        number = joint.get("joint")
        zero = zeros.get(int(number)) if isinstance(number, int) else None
        value = f"{zero:+.5f} deg" if isinstance(zero, (int, float)) else "as it is"
        lines.append(f"note: J{number} was not calibrated by {run}"
                     f" ({joint.get('reason') or 'not determined'}); the reference takes its "
                     f"present zero ({value}) as good, and every later run with it is only as "
                     "right as that zero: record at commissioning or right after a verified "
                     "full calibration")
    return lines


def run_show(args: argparse.Namespace) -> int:
    from hostpc.calibrate.reference import MOUNT_FLOOR_M, MOUNT_FLOOR_RAD, load_reference

    reference = load_reference(args.file)
    print(f"cell reference {args.file}: {reference.method} on {reference.robot_model or '?'}"
          f" (serial {reference.robot_serial or 'not recorded'}), recorded "
          f"{reference.recorded} by {reference.software or '?'} from "
          f"{reference.source_run or '?'}")
    for frame in reference.frames:
        value = frame.absolute()
        sigma = frame.floored_covariance().diagonal() ** 0.5
        parts = []
        for name, v, s in zip(frame.parameters, value, sigma, strict=True):
            if name.rsplit(".", 1)[-1] in ("rx", "ry", "rz"):
                parts.append(f"{name} {math.degrees(v):+.4f} +- {math.degrees(s):.4f} deg")
            else:
                parts.append(f"{name} {v * 1e3:+.3f} +- {s * 1e3:.4f} mm")
        print(f"  {frame.name}: " + ", ".join(parts))
    print(f"  (sigmas include the mount floor {MOUNT_FLOOR_M * 1e6:g} um / "
          f"{math.degrees(MOUNT_FLOOR_RAD):g} deg)")
    return 0
