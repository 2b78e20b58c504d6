"""Write the sample outputs in the docs from the tool itself, so they cannot drift.

    python docs/generate_samples.py            # rewrite every sample block in docs/*.md
    python docs/generate_samples.py --check    # exit 1 naming each block that differs
    python docs/generate_samples.py --check --fast   # skip the blocks marked slow

A sample block is a fenced block between two marker comments; the first names the command
and what of its output to show:

    <!-- sample: hostpc diagnose examples/ur5e_stereo.json; show=diagnose,verdict -->
    ```
    $ hostpc diagnose examples/ur5e_stereo.json
    ... (written by this script)
    ```
    <!-- /sample -->

Options after the command, separated by ``;``:
- ``show=NAME,NAME:N,NAME:-N``: the sections of the output to show (a section is a line at
  column 0 with the indented lines under it, named by the start of that line:
  ``verdict``, ``candidate effects``, ``advice:``, ``ladder:``); ``NAME:N`` keeps its first
  N lines, ``NAME:-N`` its last N (the rest is ``  ...``); sections left out between two
  shown ones are one ``...`` line. Without ``show`` the whole output.
- ``grep=REGEX``: then only the lines that match REGEX (a table's header and two rows).
- ``prepare=NAME``: make the files the command reads first (``PREPARE`` below: a dataset
  with an outlier, a dataset whose zero drifts, a calibration run on the simulator, a
  recorded one).
- ``prompt=no``: no ``$ command`` line.
- ``slow``: the block needs a calibration run (skipped with ``--fast``).

Commands run in-process (``hostpc.cli.main``) in a scratch folder holding links to
``examples/`` and ``controller_stub/``, so the paths in the docs are the paths the command
reads and nothing is written into the repository; the port the OS chose for a simulated
controller is shown as ``127.0.0.1:PORT``. Run it with the venv's Python;
``tests/integration/test_docs_samples.py`` runs ``--check`` in CI.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import re
import shlex
import sys
import tempfile
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
LINKED = ("examples", "controller_stub")
#: the simulator's port, chosen by the OS for each run: shown as PORT
LOOPBACK_PORT = re.compile(r"127\.0\.0\.1:\d+")

BLOCK = re.compile(r"(?P<open><!-- sample: (?P<spec>.*?) -->\n)```[^\n]*\n(?P<body>.*?)```\n"
                   r"(?P<close><!-- /sample -->)", re.S)


@dataclass(frozen=True)
class Sample:
    """One marker's command and options."""

    command: str
    show: tuple[str, ...] = ()
    grep: str | None = None
    prepare: str | None = None
    prompt: bool = True
    slow: bool = False


def parse_spec(spec: str) -> Sample:
    """``COMMAND; show=...; prepare=...; prompt=no; slow`` -> Sample."""
    command, *options = [part.strip() for part in spec.split(";")]
    fields: dict[str, object] = {}
    for option in options:
        key, _, value = option.partition("=")
        if key == "show":
            fields["show"] = tuple(v.strip() for v in value.split(",") if v.strip())
        elif key == "grep":
            fields["grep"] = value
        elif key == "prepare":
            fields["prepare"] = value
        elif key == "prompt":
            fields["prompt"] = value != "no"
        elif key == "slow":
            fields["slow"] = True
        else:
            raise SystemExit(f"sample {command!r}: unknown option {option!r}")
    return Sample(command, **fields)  # type: ignore[arg-type]


# --- what a command reads, made on the fly -------------------------------------------------

def _outlier_dataset(work: Path) -> None:
    """outlier.json: the hidden-compliance example with sample 10 moved by 10 m."""
    document = json.loads((work / "examples" / "ur5e_stereo_hidden_compliance.json").read_text())
    sample = document["samples"][10]
    sample["p"][0] += 10.0  # x, in metres
    (work / "outlier.json").write_text(json.dumps(document))


def _drift_dataset(work: Path) -> None:
    """drift.json: a synthetic UR5e dataset whose joint 3 zero creeps with time (an effect
    in no library; tests/hostpc/test_diagnose_auto_effect.py builds the same)."""
    sys.path.insert(0, str(ROOT))
    from hostpc.dataset import save_dataset
    from tests.hostpc.diagnose_support import hidden_dataset, inject
    from tests.hostpc.test_diagnose_auto_effect import DRIFT, ZeroDrift

    synthetic, _ = inject(hidden_dataset({}, seed=4), ZeroDrift(), {"zero_drift.k": DRIFT})
    save_dataset(synthetic.dataset, work / "drift.json")


def _hidden_run(work: Path) -> None:
    """runs/hidden: the README's calibration on the world with a hidden compliance."""
    run_main(["calibrate", "--robot", "sim", "--scenario",
              "controller_stub/scenarios/stereo_hidden_compliance.yaml", "--known", "target",
              "--no-push", "--no-report", "--out", "runs/hidden"])


#: the camera-free recipe of docs/vision.md, first step: a recorded simulator run, whose
#: recording holds the chessboard pairs the rig was calibrated from
RECORDED_RUN = "hostpc calibrate --robot sim --record --no-report --out runs/recorded"


def _recorded_run(work: Path) -> None:
    run_main(shlex.split(RECORDED_RUN)[1:])


PREPARE: dict[str, Callable[[Path], None]] = {
    "recorded_run": _recorded_run,
    "outlier_dataset": _outlier_dataset,
    "drift_dataset": _drift_dataset,
    "hidden_run": _hidden_run,
}


# --- running and cutting ---------------------------------------------------------------------

def run_main(argv: list[str]) -> str:
    """`hostpc ARGV` in-process; its standard output (progress on stderr is dropped)."""
    from hostpc.cli.main import main

    out = io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(io.StringIO()):
        main(argv)
    return LOOPBACK_PORT.sub("127.0.0.1:PORT", out.getvalue())


def sections(text: str) -> list[tuple[str, list[str], bool]]:
    """(first line, its lines, a blank line before it) per section of an output."""
    found: list[tuple[str, list[str], bool]] = []
    blank = False
    for line in text.rstrip("\n").split("\n"):
        if not line.strip():
            blank = True
            continue
        if line[0] != " " or not found:
            found.append((line, [line], blank))
        else:
            found[-1][1].append(line)
        blank = False
    return found


def cut(text: str, show: tuple[str, ...]) -> list[str]:
    """The lines of ``text`` that ``show`` selects (module docstring)."""
    if not show:
        return text.rstrip("\n").split("\n")
    parts = sections(text)
    lines: list[str] = []
    last = -1
    for selector in show:
        numbered = re.fullmatch(r"(.*):(-?\d+)", selector)  # "advice::-1": name "advice:"
        name, count = numbered.groups() if numbered else (selector, "")
        index = next((k for k, (head, _, _) in enumerate(parts)
                      if k > last and head.startswith(name)), None)
        if index is None:
            raise SystemExit(f"no section {name!r} after section {last} of:\n{text}")
        head, body, blank = parts[index]
        if index != last + 1:
            lines.append("...")
        elif blank and lines:
            lines.append("")
        if count:
            n = int(count)
            if n >= 0:
                body = body[:1 + n] + (["  ..."] if len(body) > 1 + n else [])
            else:
                body = body[:1] + (["  ..."] if len(body) > 1 - n else []) + body[n:]
        lines += body
        last = index
    return lines


@contextlib.contextmanager
def scratch() -> Iterator[Path]:
    """A scratch working folder with links to the repository's inputs."""
    with tempfile.TemporaryDirectory(prefix="zerocal-docs-") as name:
        work = Path(name)
        for entry in LINKED:
            (work / entry).symlink_to(ROOT / entry, target_is_directory=True)
        here = Path.cwd()
        os.chdir(work)
        try:
            yield work
        finally:
            os.chdir(here)


def render(sample: Sample, work: Path, outputs: dict[str, str], prepared: set[str]) -> str:
    """The fenced block's body for one sample."""
    if sample.prepare and sample.prepare not in prepared:
        PREPARE[sample.prepare](work)
        prepared.add(sample.prepare)
    if sample.command not in outputs:
        argv = shlex.split(sample.command)
        if argv[0] != "hostpc":
            raise SystemExit(f"sample {sample.command!r}: only hostpc commands")
        outputs[sample.command] = run_main(argv[1:])
    lines = cut(outputs[sample.command], sample.show)
    if sample.grep:
        lines = [line for line in lines if re.search(sample.grep, line)]
    lines = ([f"$ {sample.command}"] if sample.prompt else []) + lines
    return "\n".join(lines) + "\n"


def generate(paths: list[Path], check: bool, fast: bool) -> list[str]:
    """Rewrite (or, with ``check``, compare) every sample block; the blocks that differ."""
    differ: list[str] = []
    outputs: dict[str, str] = {}
    prepared: set[str] = set()
    with scratch() as work:
        for path in paths:
            text = path.read_text(encoding="utf-8")

            def replace(match: re.Match[str], path: Path = path) -> str:
                sample = parse_spec(match.group("spec"))
                if fast and sample.slow:
                    return match.group(0)
                body = render(sample, work, outputs, prepared)
                if body != match.group("body"):
                    shown = path.relative_to(ROOT) if path.is_relative_to(ROOT) else path
                    differ.append(f"{shown}: {sample.command}")
                return f"{match.group('open')}```\n{body}```\n{match.group('close')}"

            new = BLOCK.sub(replace, text)
            if not check and new != text:
                path.write_text(new, encoding="utf-8")
    return differ


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--check", action="store_true",
                        help="write nothing; exit 1 naming each block that differs")
    parser.add_argument("--fast", action="store_true", help="skip the blocks marked slow")
    parser.add_argument("files", nargs="*", type=Path, help="default: docs/*.md")
    args = parser.parse_args(argv)
    paths = [p.resolve() for p in args.files] or sorted(DOCS.glob("*.md"))
    differ = generate(paths, args.check, args.fast)
    for entry in differ:
        print(("drifted: " if args.check else "rewritten: ") + entry)
    if args.check and differ:
        print("run `python docs/generate_samples.py` to write them again")
        return 1
    return 0


if __name__ == "__main__":
    sys.path.insert(0, str(ROOT))
    try:
        import pytest  # noqa: F401  (the drift sample's synthetic world lives in tests/)
    except ModuleNotFoundError:
        print("docs/generate_samples.py needs the test extras (its drift sample is built by "
              "tests/hostpc): .venv/bin/pip install '.[test]'", file=sys.stderr)
        raise SystemExit(2) from None
    raise SystemExit(main())
