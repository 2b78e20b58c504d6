"""`hostpc report RUN` / `hostpc report DATASET.json`: a calibration run's report.html
written again from its files, offline; or the report of any dataset (an imported metrology
file, a dataset written by hand: docs/dataset-format.md).

A dataset: fitted and diagnosed with the model of ``--effects``, ``--loss``, ``--plugin``
(as `hostpc fit` and `hostpc diagnose` take them; ``--robot`` to read it with another
robot), and rendered by the same renderer as `hostpc diagnose --report`
(``hostpc.report.write_report``), to ``--out`` (default: DATASET with ``.html``).

A run: reads RUN/result.json (the verdict, offsets, verification, truth comparison), diagnoses
RUN/dataset.json with the run's model (effects, plugins, loss as recorded in the result's
settings) and, for a simulated run, reads RUN/sim/truth.json for the effect sizes. Works on
runs of older versions too: what their result lacks is left out of the report.
Exit codes: 0 written; 2 bad input (no run folder nor dataset file, no or malformed
result.json, a malformed dataset, a report path that cannot be written).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from hostpc.errors import InputError
from hostpc.input_files import CONFIG, read_input_text
from hostpc.json_object import JsonObject


def register(subparsers: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    parser = subparsers.add_parser(
        "report",
        help="write the HTML report of a calibration run, or of a dataset (no robot)",
        description=("RUN: render RUN/report.html from RUN/result.json and RUN/dataset.json: "
                     "the verdict, offsets table, verification and (simulated runs) the truth "
                     "comparison, then the diagnosis. DATASET.json: fit and diagnose it with "
                     "the model of --effects/--loss/--plugin (as hostpc fit) and render "
                     "the diagnosis report. See docs/diagnostics.md."),
    )
    parser.add_argument("run", metavar="RUN|DATASET.json",
                        help="run folder of `hostpc calibrate` (holds result.json), or a "
                        "dataset file (zerocal-dataset/1 JSON)")
    parser.add_argument("--out", metavar="FILE.html",
                        help="where to write (default RUN/report.html; for a dataset, the "
                        "dataset's path with .html)")
    parser.add_argument("--no-diagnosis", action="store_true",
                        help="a run: only the result (skip diagnosing the dataset)")
    from hostpc.cli.fit import add_model_options
    from hostpc.cli.robot_options import add_robot_override

    add_model_options(parser)
    add_robot_override(parser)
    parser.set_defaults(func=run)


def read_json(path: Path, what: str) -> JsonObject:
    """A JSON object from ``path``; InputError naming the file otherwise."""
    if not path.exists():
        raise InputError(f"{path}: no {what} here")
    try:
        document = json.loads(read_input_text(path, CONFIG))  # regular file, bounded
    except (OSError, ValueError, RecursionError) as exc:
        raise InputError(f"{path}: cannot read the {what}: {exc}") from exc
    if not isinstance(document, dict):
        raise InputError(f"{path}: the {what} is not a JSON object")
    return document


def _unfinished(folder: Path) -> str:
    """Why a run folder without result.json has no report, and what to do: a run whose
    push was rolled back since has nothing to finish on the controller."""
    from hostpc.calibrate.journal import Journal
    from hostpc.calibrate.journal_events import Pushed, Rollback
    from hostpc.calibrate.next_commands import resume_command
    from hostpc.calibrate.run_header import read_run_header
    from hostpc.cli.rollback import status_hint

    journal = Journal(folder)
    try:
        archive = read_run_header(journal).archive
        last = journal.last_event(Pushed, Rollback)
    except InputError:
        archive, last = None, None
    if isinstance(last, Rollback):
        return (f"{folder}: no result.json: the run stopped after its push, and the push "
                f"was rolled back ({last.time or 'at an unrecorded time'}): the controller "
                f"has its previous offsets, nothing of the run is left on it; to calibrate it "
                f"again: {resume_command(folder, '--push', archive=archive)}, then hostpc "
                f"report {folder} ({status_hint(folder)})")
    return (f"{folder}: no result.json: the run did not finish (ERROR); finish it with "
            f"{resume_command(folder, archive=archive)}, then hostpc report {folder} "
            f"({status_hint(folder)})")


def run(args: argparse.Namespace) -> int:
    from hostpc.report import write_calibration_report

    folder = Path(args.run)
    if folder.is_file():
        return _dataset_report(args)
    if not folder.is_dir():
        raise InputError(f"{folder}: not a run folder nor a dataset file")
    given = [option for option, value in (("--effects", args.effects), ("--plugin", args.plugin),
                                          ("--loss", args.loss != "linear"),
                                          ("--robot", args.robot)) if value]
    if given:
        raise InputError(f"{folder}: a run's report uses the model the run recorded; "
                         f"{', '.join(given)}: for the report of a dataset, hostpc report "
                         f"{folder / 'dataset.json'} {' '.join(given)} ...")
    if not (folder / "result.json").exists() and (folder / "run.json").is_file():
        raise InputError(_unfinished(folder))
    result = read_json(folder / "result.json", "result document (result.json)")
    diagnosis = None
    dataset = folder / "dataset.json"
    if not args.no_diagnosis and dataset.is_file():
        from hostpc.diagnostics import diagnose

        settings = result.get("settings") or {}
        effects = (result.get("fit") or {}).get("effects") or settings.get("effects")
        diagnosis = diagnose(dataset, effects, plugins=settings.get("plugins") or [],
                             loss=settings.get("loss") or "linear", source=str(dataset))
    truth_file = folder / "sim" / "truth.json"
    truth = read_json(truth_file, "simulator truth") if truth_file.is_file() else None
    out = Path(args.out) if args.out else folder / "report.html"
    try:
        write_calibration_report(out, result, diagnosis, truth)
    except OSError as exc:
        raise InputError(f"{out}: cannot write the report ({exc.strerror or exc})") from exc
    print(f"report written to {out}")
    return 0


def _dataset_report(args: argparse.Namespace) -> int:
    """`hostpc report DATASET.json`: the dataset fitted and diagnosed with the model asked
    for, its report written by the diagnosis report's renderer."""
    from hostpc.cli.robot_options import robot_options
    from hostpc.cli.robots import load_dataset_as_asked
    from hostpc.diagnostics import diagnose
    from hostpc.report import write_report

    if args.no_diagnosis:
        raise InputError("--no-diagnosis: a dataset's report is its diagnosis; the option is "
                         "for a run folder")
    if args.cv_folds < 0:
        raise InputError(f"--cv-folds {args.cv_folds}: must not be negative")
    if args.effects and "auto" in [e.strip() for e in args.effects.split(",")]:
        raise InputError("--effects auto: give the model (hostpc fit DATASET --effects auto "
                         "names the one it chooses)")
    source = load_dataset_as_asked(args.run, args) if args.robot else args.run
    diagnosis = diagnose(source, args.effects, plugins=args.plugin, cv_folds=args.cv_folds,
                         loss=args.loss, source=args.run, data_options=robot_options(args))
    out = Path(args.out) if args.out else Path(args.run).with_suffix(".html")
    try:
        write_report(out, diagnosis)
    except OSError as exc:
        raise InputError(f"{out}: cannot write the report ({exc.strerror or exc})") from exc
    print(f"report written to {out}")
    return 0
