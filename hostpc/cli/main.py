"""`hostpc` command line: one subcommand per module in hostpc.cli.

Each command module exposes `register(subparsers)` which adds its parser and sets
`func=run` where `run(args) -> int` returns the exit code. Errors derived from
`hostpc.errors.ZerocalError` become one line on stderr and their `exit_code`; nothing
else prints a traceback unless `--debug` is given.
"""

from __future__ import annotations

import os

# zerocal's matrices are small (tens of parameters): BLAS worker threads only compete with each
# other on them (hostpc diagnose --ladder: 2.5 s -> 1.3 s on 2 cores). Set before numpy loads;
# a user's own setting wins.
for _variable in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_variable, "1")

import argparse  # noqa: E402
import gc  # noqa: E402
import importlib  # noqa: E402
import sys  # noqa: E402
import typing  # noqa: E402
import warnings  # noqa: E402

from hostpc.errors import InputError, ZerocalError  # noqa: E402
from hostpc.robots import warm_stub  # noqa: E402

COMMAND_MODULES = (
    "fit",
    "status",
    "diagnose",
    "calibrate",
    "rollback",
    "stereo_calibrate",
    "report",  # hostpc.report: re-render a run's report offline
    "camera",  # hostpc.sensors: serve or check the host's stereo camera
    "station",  # hostpc.station: the end-of-line station service
    "history",  # hostpc.archive: archived runs and drift
    "robots",  # hostpc.kinematics: built-in robots and URDF chains
    "import_csv",  # hostpc.importing: metrology CSV -> dataset
    "push",  # push the offsets of an offline fit
    "predict",  # hostpc.fitting: a saved fit against a dataset it never saw
    "reference",  # hostpc.calibrate.reference: record / show a cell reference
)


class _OneLineErrors(argparse.ArgumentParser):
    """Bad options are one line on stderr (no usage block) and exit code 2."""

    def error(self, message: str) -> typing.NoReturn:
        self.exit(2, f"{self.prog}: error: {message}\n")


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The parser of every command; with ``command`` (the one on the command line), of that
    command only if its module registers it (a command's module may import much: `hostpc
    diagnose` need not load what `hostpc calibrate` needs), else of every command."""
    if command is not None and command.replace("-", "_") in COMMAND_MODULES:
        parser = _parser((command.replace("-", "_"),))
        subparsers = next(a for a in parser._actions
                          if isinstance(a, argparse._SubParsersAction))
        if command in subparsers.choices:
            return parser
    return _parser(COMMAND_MODULES)


def _parser(modules: tuple[str, ...]) -> argparse.ArgumentParser:
    parser = _OneLineErrors(
        prog="hostpc",
        description="zerocal host: calibrate robot joint zero offsets, fit and diagnose datasets.",
    )
    parser.add_argument("--debug", action="store_true", help="show tracebacks on errors")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in modules:
        try:
            module = importlib.import_module(f"hostpc.cli.{name}")
        except ModuleNotFoundError as exc:
            if exc.name == f"hostpc.cli.{name}":
                continue  # command not built yet
            raise
        module.register(subparsers)
    _add_token_file_options(subparsers)
    return parser


def _add_token_file_options(subparsers: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    """Every command with --token also takes --token-file (read in `main`)."""
    for command in subparsers.choices.values():
        options = {o for action in command._actions for o in action.option_strings}
        if "--token" in options and "--token-file" not in options:
            command.add_argument("--token-file", metavar="FILE",
                                 help="read the shared token from FILE (mode 0600)")
        for action in command._actions:  # a command's own actions (`camera serve`)
            if isinstance(action, argparse._SubParsersAction):
                _add_token_file_options(action)


def _token_from_options(args: argparse.Namespace) -> None:
    """--token-file -> args.token; a warning for a token given on the command line."""
    token_file = getattr(args, "token_file", None)
    if getattr(args, "token", None) is None and token_file is None:
        return  # hostpc.robots.connect imports the socket protocol: only where it is used
    from hostpc.robots.connect import TOKEN_ON_COMMAND_LINE_WARNING, read_token_file

    if getattr(args, "token", None) is not None:
        if token_file is not None:
            raise InputError("--token and --token-file: give one of them")
        if not args.token.strip():
            raise InputError("--token: the token is empty")
        print(f"hostpc {args.command}: {TOKEN_ON_COMMAND_LINE_WARNING}", file=sys.stderr)
    elif token_file is not None:
        args.token = read_token_file(token_file)


def main(argv: list[str] | None = None) -> int:
    words = sys.argv[1:] if argv is None else argv
    command = next((w for w in words if not w.startswith("-")), None)
    if warm_stub.wants_simulator(command, words):  # its start-up overlaps ours (warm_stub.py)
        warm_stub.prestart()
    try:
        return _main(argv, command)
    finally:
        warm_stub.discard()  # a simulator the command did not take
        if argv is None:  # the process's own command: it ends now
            exit_without_collecting()


def exit_without_collecting() -> None:
    """Spare the ending process the interpreter's last garbage collections: they visit every
    object of the ~500 modules a command imports (0.1-0.3 s of `hostpc diagnose`, more than
    its start-up); `gc.freeze` leaves the objects that exist now out of them. atexit handlers
    and the flushing of the standard streams run as ever; objects in reference cycles are
    left to the process's end (every file a command writes is closed by then)."""
    gc.freeze()


def _main(argv: list[str] | None, command: str | None) -> int:
    collecting = gc.isenabled()
    gc.disable()  # the command's imports: ~10^5 objects and no garbage
    try:
        parser = build_parser(command)
    finally:
        if argv is None:  # the process's own command: they live as long as it does, and
            gc.freeze()  # no later collection need visit them (0.1-0.2 s of a calibration)
        if collecting:
            gc.enable()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # a bad option (one line already printed) or --help
        return exc.code if isinstance(exc.code, int) else 2
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    try:
        _token_from_options(args)
        with warnings.catch_warnings():
            if not args.debug:  # numpy's overflow/invalid warnings are not for the user
                warnings.simplefilter("ignore", RuntimeWarning)
            return int(args.func(args))
    except ZerocalError as exc:
        if args.debug:
            raise
        print(f"hostpc {args.command}: error: {exc}", file=sys.stderr)
        return exc.exit_code
    except KeyboardInterrupt:
        print(f"hostpc {args.command}: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # e.g. `hostpc fit ... | head`: the reader went away
        import os

        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 141


if __name__ == "__main__":
    sys.exit(main())
