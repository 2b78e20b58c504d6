"""`hostpc calibrate`: measure the robot, fit, push compensated zero offsets, verify.

    hostpc calibrate --robot HOST[:PORT] --method stereo_target [--poses N] [--effects ...]
                     [--rig FILE] [--known tool,target] [--cell FILE] [--push/--no-push]
                     [--force] [--out DIR] [--json]
    hostpc calibrate --robot sim [--scenario FILE]     the simulated controller, with truth
    hostpc calibrate --method sphere_probe [--probe-io modbus [--modbus HOST[:PORT]]]
                                                       touch probe; contacts by the guarded
                                                       move or by polling over Modbus
    hostpc calibrate --resume DIR [--force] [--push/--no-push] [--max-correction DEG]
                                                       continue an interrupted run (the push
                                                       options may change: they act after
                                                       the measurements)
    hostpc calibrate --resume DIR --separate A,B       measure the poses that tell two
                                                       confounded candidates apart, test again

Everything lands in the run folder (DIR): run.json (settings, seed, plan), journal.jsonl
(every pose as measured), rig.json, dataset.json, fit.json, push.json (rollback id and the
previous offsets), verify.json, result.json, summary.txt and report.html. Progress goes to
stderr; the summary (or, with --json, the result document) to stdout.

Exit codes: 0 done (verification passed or not run), 2 bad input, 3 controller unreachable
or link lost (resume with --resume DIR), 4 controller refused / failed, 5 push refused by a
guard rail, 6 verification of the pushed offsets failed, 7 a joint of --require-joints not
calibrated from the data (the others still pushed and verified), 130 / 143 interrupted by Ctrl-C /
SIGTERM (resume with --resume DIR). See docs/calibrate.md.
"""

from __future__ import annotations

import argparse
import asyncio
import dataclasses
import datetime as _dt
import json
import shutil
import sys
import types
from pathlib import Path
from typing import Any, NoReturn

from hostpc.calibrate.journal import Journal
from hostpc.calibrate.next_commands import resume_command
from hostpc.calibrate.outcome import parse_required_joints
from hostpc.calibrate.resume import ResumeOverrides
from hostpc.calibrate.run_header import parse_run_header, read_run_header
from hostpc.calibrate.run_plan import PlanningError
from hostpc.calibrate.run_values import RobotInfo, RunOutcome
from hostpc.calibrate.runner import Runner
from hostpc.calibrate.separate import parse_separate
from hostpc.calibrate.swaps import DEFAULT_SWAP_LIMIT_DEG, parse_swapped
from hostpc.cli.archive_options import add_archive_options, archive_run, run_archive
from hostpc.cli.calibrate_checks import (
    check_known_frames,
    check_model_options,
    check_out_folder,
    check_reference_option,
)
from hostpc.cli.fit import add_constraint_options, add_model_options
from hostpc.cli.kind_options import add_kind_options, kind_option_values
from hostpc.cli.numbers import finite, integer
from hostpc.cli.pose_counts import pose_counts
from hostpc.cli.progress import StderrProgress
from hostpc.cli.termination import (
    EXIT_INTERRUPTED,
    EXIT_TERMINATED,
    Terminated,
    cancel_on_sigterm,
    interrupt_notes,
    sigterm_as_interrupt,
)
from hostpc.dataset.kind_registry import DEFAULT_METHOD
from hostpc.db_url import redacted_url
from hostpc.errors import InputError, ZerocalError
from hostpc.json_object import JsonObject
from hostpc.methods.base import RunSettings
from hostpc.methods.cell import load_cell_file, parse_known
from hostpc.robots.connect import RobotAddress, open_robot, parse_robot, resolve_token
from hostpc.robots.drivers import DEFAULT_DRIVER, DRIVER_NAMES, SIM_DRIVER, check_sim_driver
from hostpc.sensors.calibrate_options import (
    add_sensor_options,
    check_replay_options,
    check_sensor_options,
    open_with_sensors,
    replay_inputs,
    robot_camera,
)

SIM_FOLDER = "sim"
MODBUS_PORT = 502
POSITIVE = finite(above=0.0)
COUNT = integer(least=1)
"""Default Modbus TCP port of `--modbus HOST` (and of a robot without --modbus)."""


def register(subparsers: Any) -> None:
    """Add the `calibrate` subcommand."""
    parser = subparsers.add_parser(
        "calibrate",
        help="measure the robot, fit, push compensated zero offsets and verify",
        description=(
            "Drive the robot through informative poses, measure them, fit the error model, "
            "push the compensated zero offsets (guarded) and verify on fresh poses. "
            "`--robot sim` runs against the simulated controller and compares with its truth."
        ),
    )
    parser.add_argument("--robot", metavar="HOST[:PORT]|sim",
                        help="controller address, or `sim` for the simulated controller")
    parser.add_argument("--driver", choices=DRIVER_NAMES, default=DEFAULT_DRIVER,
                        help="robot driver (default zerocal)")
    parser.add_argument("--token", help="shared token (default: $ZEROCAL_TOKEN, else the "
                        "simulator's default)")
    parser.add_argument("--timeout", type=POSITIVE, default=10.0, help="seconds per request")
    parser.add_argument("--method", default=DEFAULT_METHOD,
                        help=f"measurement method: a kind with a live acquisition, built in "
                        f"or a plugin's (--plugin); default {DEFAULT_METHOD}")
    parser.add_argument("--poses", type=COUNT, default=None,
                        help="fit poses (default: the fewest that reach --target-sigma, at "
                        "least 6, plus 2 check poses, at most 60; sphere_probe whole probe "
                        "orientations); --poses N alone measures exactly N")
    parser.add_argument("--verify-poses", type=integer(least=0), default=None,
                        help="fresh verification poses after the push (default: 4 with a "
                        "target sigma, chosen for the chi-square test's power, else 10; "
                        "0 = none)")
    parser.add_argument("--seed", type=int, default=0, help="planning seed (default 0)")
    add_model_options(parser)
    parser.add_argument("--known", metavar="FRAMES",
                        help="frames measured in the cell and held fixed: tool,target or none "
                        "(default: the cell's; for a controller: none)")
    parser.add_argument("--cell", metavar="FILE", help="cell description JSON (mount, target)")
    parser.add_argument("--reference", metavar="FILE|none",
                        help="cell reference (hostpc reference record): its frames enter the "
                        "fit as priors so every joint is calibrated, and are checked against "
                        "the data; on --resume: replace the run's, or none to drop it")
    add_kind_options(parser)  # the rig, --depth, --probe-io, ... (the kinds')
    parser.add_argument("--push", action=argparse.BooleanOptionalAction, default=None,
                        help="write the compensated offsets to the controller (default yes; "
                        "on a resume after a rollback: push again)")
    parser.add_argument("--force", action="store_true", default=None,
                        help="push despite a guard rail (a correction beyond "
                        "--max-correction, a fit that did not converge or does not explain "
                        "the measurements; on a resume: push again after a rollback)")
    parser.add_argument("--max-correction", type=POSITIVE, default=None, metavar="DEG",
                        help="largest correction pushed without --force (default 2 deg)")
    parser.add_argument("--swapped", metavar="J3[,J5]", default=None,
                        help="joints whose motor was swapped: their push limit is "
                        "--swap-limit, the others keep --max-correction")
    parser.add_argument("--swap-limit", type=POSITIVE, default=None, metavar="DEG",
                        help="push limit of a --swapped joint (default 45 deg)")
    parser.add_argument("--require-joints", metavar="all|none|1,2,6", default=None,
                        help="joints that must be calibrated from the data: one that is not "
                        "(unidentifiable, held, prior-dominated) makes the verdict "
                        "JOINTS_MISSING, exit 7, even though the others are pushed and "
                        "verified (default none; the station passes all)")
    add_constraint_options(parser)
    parser.add_argument("--verify-alpha", type=finite(above=0.0, below=1.0), default=None,
                        metavar="P",
                        help="false-FAIL rate of the verification's chi-square test "
                        "(default 0.01; docs/calibrate.md)")
    parser.add_argument("--verify-tolerance", type=POSITIVE, default=None, metavar="MM",
                        help="station tolerance: verification also FAILs if the RMS after "
                        "the push exceeds MM (default: none)")
    parser.add_argument("--verify-factor", type=POSITIVE, default=None, metavar="F",
                        help="the verification test takes the measurement noise as F x the "
                        "stated noise (default 1)")
    parser.add_argument("--speed", type=finite(above=0.0, most=1.0), default=0.5,
                        help="motion speed (0, 1]")
    parser.add_argument("--criterion", choices=("D", "random"), default="D",
                        help="pose selection (default D-optimal)")
    parser.add_argument("--target-sigma", type=POSITIVE, default=None, metavar="DEG",
                        help="stop adding fit poses once every identifiable joint offset's "
                        "predicted sigma is <= DEG (then --poses is the most; default "
                        "unless --poses is given: the method's own; built-in 0.002 deg, "
                        "dual_loop 0.02)")
    parser.add_argument("--candidates", type=COUNT, default=1500,
                        help="candidate pool size of the planner (default 1500)")
    parser.add_argument("--scenario", metavar="FILE", help="with --robot sim: scenario file")
    parser.add_argument("--time-scale", type=finite(least=0.0), default=0.0,
                        help="with --robot sim: wall seconds per simulated second (default 0)")
    parser.add_argument("--out", metavar="DIR", help="run folder (default ./zerocal-runs/...)")
    add_archive_options(parser, read=False)
    parser.add_argument("--resume", metavar="DIR", help="continue the run in DIR")
    parser.add_argument("--separate", metavar="A,B",
                        help="with --resume: measure the fewest extra poses that tell two "
                        "confounded candidate effects apart (hostpc diagnose names them), "
                        "append them to the run's data and test the pair again")
    parser.add_argument("--no-report", action="store_true", help="skip report.html")
    parser.add_argument("--check", action="store_true",
                        help="only check the options and the files they name (rig, cell, "
                             "reference, effects, ...), connect to nothing, exit 0 (the "
                             "station checks its config so)")
    parser.add_argument("--json", action="store_true", help="print the result document")
    add_sensor_options(parser)
    parser.set_defaults(func=run, option_defaults={  # a --replay refuses changed options
        a.dest: ("/".join(a.option_strings), a.default) for a in parser._actions
        if a.option_strings})
    parser.error = types.MethodType(_one_line_error, parser)


# ---------------------------------------------------------------- option values
# Every numeric option is checked by the parser: finite and in range, else one line, exit 2.

def _one_line_error(parser: argparse.ArgumentParser, message: str) -> NoReturn:
    """A bad option: one line on stderr, exit 2 (no usage block)."""
    parser.exit(2, f"hostpc calibrate: error: {message}\n")


def _settings(args: argparse.Namespace) -> RunSettings:
    args.poses, args.verify_poses, args.target_sigma = pose_counts(args)
    if args.poses < 1:
        raise InputError(f"--poses {args.poses}: must be at least 1")
    if args.verify_poses < 0:
        raise InputError(f"--verify-poses {args.verify_poses}: must not be negative")
    if not 0.0 < args.speed <= 1.0:
        raise InputError(f"--speed {args.speed}: must be in (0, 1]")
    max_correction = 2.0 if args.max_correction is None else args.max_correction
    if not max_correction > 0:
        raise InputError(f"--max-correction {args.max_correction}: must be positive")
    if args.candidates < args.poses + args.verify_poses:
        raise InputError(f"--candidates {args.candidates}: fewer than --poses + --verify-poses")
    if args.target_sigma is not None and not args.target_sigma > 0:
        raise InputError(f"--target-sigma {args.target_sigma}: must be positive")
    if args.timeout <= 0:
        raise InputError(f"--timeout {args.timeout}: must be positive")
    options = kind_option_values(args, args.method, tuple(args.plugin))
    return RunSettings(
        method=args.method, n_poses=args.poses, n_verify=args.verify_poses, seed=args.seed,
        effects=args.effects, plugins=tuple(args.plugin), loss=args.loss,
        cv_folds=args.cv_folds, speed=args.speed, push=args.push is not False,
        force=bool(args.force), max_correction_deg=max_correction,
        verify_factor=1.0 if args.verify_factor is None else args.verify_factor,
        verify_alpha=0.01 if args.verify_alpha is None else args.verify_alpha,
        verify_tolerance_mm=args.verify_tolerance,
        criterion=args.criterion, n_candidates=args.candidates, options=options,
        target_sigma_deg=args.target_sigma, priors=tuple(args.prior),
        swapped=parse_swapped(args.swapped),
        swap_limit_deg=(DEFAULT_SWAP_LIMIT_DEG if args.swap_limit is None
                        else args.swap_limit),
        hold=tuple(args.hold), require_joints=args.require_joints,
    )


def _run_plugins(args: argparse.Namespace) -> tuple[str, ...]:
    """The plugins a resume's effects come from: --plugin, else the run's own."""
    if args.plugin or not args.resume:
        return tuple(args.plugin)
    try:
        return read_run_header(Journal(Path(args.resume))).settings.plugins
    except ZerocalError:  # the resume itself says what is wrong with the run
        return ()


def _default_out(method: str) -> Path:
    stamp = _dt.datetime.now().strftime("%Y%m%d-%H%M%S")
    return Path("zerocal-runs") / f"{stamp}-{method}"


def _check_rig(settings: RunSettings) -> None:
    """A bad --rig file fails before anything connects or moves (exit code 2)."""
    rig = settings.options.get("rig")
    if rig:
        from hostpc.vision import load_rig

        load_rig(rig)


def run(args: argparse.Namespace) -> int:
    """Entry point of `hostpc calibrate`; returns the exit code."""
    check_sensor_options(args)  # --camera-*, --record, --replay (hostpc.sensors)
    try:
        parse_required_joints(args.require_joints)  # syntax; the joint count at the robot
    except ValueError as exc:
        raise InputError(str(exc)) from None
    settings: RunSettings | None = None
    cell_file = None
    known = None
    if args.separate is not None:  # one line, exit 2, before anything else
        args.separate = parse_separate(args.separate, _run_plugins(args), args.resume)
    if args.resume:
        run_dir = Path(args.resume)
        journal = Journal(run_dir)
        data = journal.read_header()
        journal.load()  # a damaged journal line: one line, exit 2, before connecting
        header = parse_run_header(data, journal)
        run_archive(args, run_dir)  # no --db: the run's own archive (next_commands.py)
        recorded = header.robot
        address = parse_robot(args.robot) if args.robot else (
            RobotAddress(sim=True) if recorded.sim else parse_robot(recorded.address))
        driver = recorded.driver
        scenario_file = None
        if args.effects is not None or args.plugin:
            check_model_options(args.effects, tuple(args.plugin))
        # a resume refits with them (run_reference.py)
        known = parse_known(args.known, tuple(args.plugin))
        check_known_frames(header.settings.method, known,
                           tuple(args.plugin) or header.settings.plugins)
        check_reference_option(args.reference, header.settings.method)
    elif args.replay:  # a recorded run again, without a robot (hostpc.sensors)
        check_replay_options(args, getattr(args, "option_defaults", {}))
        address, driver, settings, cell_file, known, run_dir = replay_inputs(args, _default_out)
        scenario_file = None
    else:
        if not args.robot:
            raise InputError("--robot HOST[:PORT] or --robot sim is required (or --resume DIR)")
        address = parse_robot(args.robot)
        driver = args.driver
        if address.sim:
            check_sim_driver(driver)
        settings = _settings(args)
        if (settings.options.get("probe_io") == "modbus" and not settings.options.get("modbus")
                and not address.sim):
            settings = _with_option(settings, "modbus", f"{address.host}:{MODBUS_PORT}")
        _check_rig(settings)
        cell_file = load_cell_file(args.cell) if args.cell else None
        known = parse_known(args.known, tuple(args.plugin))
        check_known_frames(settings.method, known, settings.plugins)
        check_reference_option(args.reference, settings.method)
        check_model_options(settings.effects, settings.plugins)
        run_dir = Path(args.out) if args.out else _default_out(settings.method)
        check_out_folder(run_dir)
        scenario_file = args.scenario
    if args.scenario and not address.sim:
        raise InputError("--scenario needs --robot sim")
    if args.check:  # every pre-flight check above passed; nothing connects or moves
        if address.sim:  # the simulator's world, loaded and checked by the simulator
            _check_sim_scenario(args, settings, run_dir, scenario_file)
        print("hostpc calibrate: options and files checked")
        return 0
    progress = StderrProgress()
    created = not run_dir.exists()
    try:
        with sigterm_as_interrupt():
            outcome = _run_with_robot(args, address, driver, run_dir, settings, cell_file,
                                      known, scenario_file, progress)
    except KeyboardInterrupt as exc:
        progress.close()
        stopped = interrupt_notes(exc)
        interrupted = f"interrupted ({stopped})" if stopped else "interrupted"
        if Journal(run_dir).exists:
            resume = resume_command(run_dir, archive=redacted_url(args.db) if args.db else None)
            print(f"hostpc calibrate: {interrupted}: continue with {resume}", file=sys.stderr)
        else:
            print(f"hostpc calibrate: {interrupted} before the run started (nothing to "
                  "resume)", file=sys.stderr)
        return EXIT_TERMINATED if isinstance(exc, Terminated) else EXIT_INTERRUPTED
    except PlanningError as exc:
        if created and not Journal(run_dir).records("fit"):  # nothing measured: no run
            shutil.rmtree(run_dir, ignore_errors=True)
            raise PlanningError(f"{exc} (nothing was measured: {run_dir} removed)") from None
        raise
    except BaseException:
        if created and not Journal(run_dir).exists:  # failed before the run started
            shutil.rmtree(run_dir, ignore_errors=True)
        raise
    finally:
        progress.close()
    if args.json:
        sys.stdout.write(json.dumps(outcome.document, indent=2, allow_nan=False))
        sys.stdout.write("\n")
    else:
        print(outcome.summary)
    archive_run(args, run_dir, outcome.exit_code)
    return outcome.exit_code


def _run_with_robot(args: argparse.Namespace, address: RobotAddress, driver: str,
                    run_dir: Path, settings: RunSettings | None, cell_file: Any,
                    known: tuple[str, ...] | None, scenario_file: str | None,
                    progress: StderrProgress) -> RunOutcome:
    if not address.sim:
        info = RobotInfo(address=str(address), driver=driver, sim=False)
        return asyncio.run(cancel_on_sigterm(_calibrate(
            args, address, driver, run_dir, settings, cell_file, known, (), info, progress,
            None, args.token)))
    from hostpc.robots.simulator import SimulatedController

    sim_dir = run_dir / SIM_FOLDER
    scenario, default_known = _sim_scenario(args, settings, run_dir, scenario_file)
    token = _sim_token(args, scenario)
    modbus_port, settings = _sim_modbus(settings, run_dir)
    progress.stage("start simulator")
    with SimulatedController(scenario, sim_dir, modbus_port=modbus_port, token=token,
                             plugins=settings.plugins if settings is not None else ()
                             ) as simulator:
        info = RobotInfo(address=f"{simulator.address.host}:{simulator.address.port}",
                         driver=SIM_DRIVER, sim=True,
                         scenario=str(Path(simulator.scenario_path).resolve()))
        return asyncio.run(cancel_on_sigterm(_calibrate(
            args, simulator.address, SIM_DRIVER, run_dir, settings, cell_file, known,
            default_known, info, progress, simulator.truth, token)))


def _sim_scenario(args: argparse.Namespace, settings: RunSettings | None, run_dir: Path,
                  scenario_file: str | None) -> tuple[JsonObject, tuple[str, ...]]:
    """The simulated world of the run and the frames its cell declares known: a resumed
    run's recorded scenario, else --scenario FILE, else the method's default world."""
    from hostpc.robots.simulator import (
        default_sim_scenario,
        load_scenario_file,
        sim_default_known,
    )

    recorded_scenario = run_dir / SIM_FOLDER / "scenario.json"
    if args.resume and recorded_scenario.is_file():
        return load_scenario_file(recorded_scenario, time_scale=None), ()
    if scenario_file:
        return load_scenario_file(scenario_file, time_scale=args.time_scale), ()
    method = settings.method if settings is not None else None
    plugins = settings.plugins if settings is not None else ()
    return (default_sim_scenario(time_scale=args.time_scale, method=method, plugins=plugins),
            sim_default_known(method, plugins))


def _sim_token(args: argparse.Namespace, scenario: JsonObject) -> str:
    """The simulator's token: --token, else the scenario's, else the default."""
    return str(args.token or (scenario.get("server") or {}).get("token")
               or resolve_token(None))


def _check_sim_scenario(args: argparse.Namespace, settings: RunSettings | None,
                        run_dir: Path, scenario_file: str | None) -> None:
    """--check with --robot sim: the scenario the run would start the simulator with, read
    and checked by the simulator itself (one line, exit 2 if it is refused), in a
    temporary folder: the run folder is not created."""
    import tempfile

    from hostpc.robots.simulator import SimulatedController

    scenario, _ = _sim_scenario(args, settings, run_dir, scenario_file)
    plugins = settings.plugins if settings is not None else ()  # as the run's simulator
    with tempfile.TemporaryDirectory(prefix="zerocal-check-") as folder:
        SimulatedController(scenario, folder, token=_sim_token(args, scenario),
                            plugins=plugins).check()


def _with_option(settings: RunSettings, key: str, value: Any) -> RunSettings:
    """settings with one method option set."""
    return dataclasses.replace(settings, options={**settings.options, key: value})


def _sim_modbus(settings: RunSettings | None, run_dir: Path
                ) -> tuple[int | None, RunSettings | None]:
    """The simulator's Modbus port for `--probe-io modbus` (None: the run does not poll
    over Modbus) and the settings pointing at it. A new run takes --modbus's port or a free
    one; a resume restarts the simulator on the port its run recorded."""
    options = (settings.options if settings is not None
               else read_run_header(Journal(run_dir)).settings.options)
    if options.get("probe_io") != "modbus":
        return None, settings
    from hostpc.kinds.sphere_probe.method import parse_modbus_address
    from hostpc.robots.simulator import free_local_port

    given = options.get("modbus")
    port = parse_modbus_address(str(given), "127.0.0.1")[1] if given else free_local_port()
    if settings is not None:
        settings = _with_option(settings, "modbus", f"127.0.0.1:{port}")
    return port, settings


async def _calibrate(args: argparse.Namespace, address: RobotAddress, driver: str,
                     run_dir: Path, settings: RunSettings | None, cell_file: Any,
                     known: tuple[str, ...] | None, default_known: tuple[str, ...],
                     info: RobotInfo, progress: StderrProgress, truth: Any,
                     token: str | None) -> RunOutcome:
    progress.stage("connect")
    robot = await open_with_sensors(  # host cameras, --record, --replay (hostpc.sensors)
        args, run_dir, settings, cell_file, known, default_known, info,
        lambda: open_robot(address, driver, token=token, timeout=args.timeout,
                           camera=robot_camera(args, driver)))
    try:
        overrides = ResumeOverrides(
            push=args.push, force=args.force, max_correction_deg=args.max_correction,
            verify_factor=args.verify_factor, verify_alpha=args.verify_alpha,
            verify_tolerance_mm=args.verify_tolerance, effects=args.effects,
            plugins=tuple(args.plugin) or None, require_joints=args.require_joints,
            swapped=parse_swapped(args.swapped) or None, swap_limit_deg=args.swap_limit,
            known=args.known, reference=args.reference, separate=args.separate)
        runner = Runner(robot, run_dir, robot_info=info, settings=settings,
                        cell_file=cell_file, known=known, default_known=default_known,
                        progress=progress, truth=truth, report=not args.no_report,
                        resume_overrides=overrides, reference=args.reference,
                        robot_serial=args.robot_serial,
                        archive=redacted_url(args.db) if args.db else None)
        return await runner.run()
    finally:
        await robot.close()
