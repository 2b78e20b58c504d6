"""Fuzz: every input file kind, damaged on purpose, through the real CLI (in-process).

Valid files (a dataset from examples/ with and without a `rig_uncertainty` block, the fit
`hostpc fit --json` writes of it, the FIGAROH CSV, the test URDF, the test plugin) are
mutated with a fixed seed (tests/hostpc/input_mutations.py: type swaps, string booleans,
null, huge and non-finite numbers, nested garbage, wrong lengths, duplicated keys, byte
flips, truncation) and given to the command that reads them. Each run must end within
TIME_BOUND_S with an exit code of the command's set, and a refusal is one line on stderr;
a traceback or a hang fails the test naming the input's index (rerun: same seed).

Mutated fit files are pushed for real (`hostpc push`) to a controller-stub on 127.0.0.1: a
push that goes ahead must leave the controller holding exactly the file's corrections (the
free joint offsets added, the held ones unchanged), and is rolled back; a refused push must
leave it untouched.

The default run feeds 1100 inputs (about 15 s); the slow variant three times as many in CI
(ZEROCAL_FUZZ_FACTOR=10 for the long run).
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import signal
import traceback
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from hostpc.cli.main import main
from hostpc.dataset import load_dataset
from tests.hostpc.input_mutations import mutate, mutate_csv, mutate_urdf

SEED = 20_251_126
ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "examples" / "ur5e_stereo.json"
URDF_FILE = ROOT / "tests" / "data" / "arm7_prismatic.urdf"
CSV_FILE = ROOT / "tests" / "data" / "figaroh_ur10e_calibration.csv"
PLUGIN_FILE = Path(__file__).with_name("distance_sensor_plugin.py")
COLUMNS = "q=shoulder_pan_joint:wrist_3_joint,x=x1,y=y1,z=z1,roll=phix1,pitch=phiy1,yaw=phiz1"
TIME_BOUND_S = 20.0
"""Longest a single command may take on a damaged file (a hang fails the test)."""
COUNTS = {"dataset": 300, "rig_dataset": 100, "fit": 400, "csv": 120, "urdf": 120,
          "plugin": 60}
"""Inputs per kind in the default run: 1100 in all."""
SLOW_FACTOR = int(os.environ.get("ZEROCAL_FUZZ_FACTOR", "3"))
"""How many times the default inputs the slow variant feeds: 3 in CI (about 1 min on 2
cores), ZEROCAL_FUZZ_FACTOR=10 for the long run (about 6.5 min: 11,000 inputs)."""


class _Hung(Exception):
    """The per-input time bound expired."""


@dataclass(frozen=True)
class Outcome:
    code: int
    out: str
    err: str


@contextlib.contextmanager
def _time_bound(seconds: float) -> Iterator[None]:
    def expire(signum: int, frame: Any) -> None:
        raise _Hung

    previous = signal.signal(signal.SIGALRM, expire)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)


def run_cli(argv: list[str]) -> Outcome | str:
    """`hostpc ARGV` in-process: its outcome, or what went wrong (a traceback, a hang)."""
    out, err = io.StringIO(), io.StringIO()
    try:
        with _time_bound(TIME_BOUND_S), contextlib.redirect_stdout(out), \
                contextlib.redirect_stderr(err):
            code = main(argv)
    except _Hung:
        return f"hung (> {TIME_BOUND_S:g} s)"
    except SystemExit as exc:
        code = exc.code if isinstance(exc.code, int) else 2
    except BaseException:
        return "traceback: " + traceback.format_exc().strip().splitlines()[-1]
    return Outcome(code, out.getvalue(), err.getvalue())


def problem(outcome: Outcome | str, allowed: set[int]) -> str | None:
    """Why an outcome breaks the contract (exit code of the set, one-line refusal), or None."""
    if isinstance(outcome, str):
        return outcome
    if outcome.code not in allowed:
        return f"exit code {outcome.code}: {outcome.err.strip()[:200]!r}"
    if "Traceback" in outcome.err:
        return f"a traceback on stderr: {outcome.err[-300:]!r}"
    lines = [line for line in outcome.err.splitlines() if line.strip()]
    if outcome.code == 2 and len(lines) != 1:
        return f"exit 2 with {len(lines)} lines on stderr: {outcome.err[:300]!r}"
    return None


def small_example() -> dict[str, Any]:
    """The example dataset cut to 15 samples (a fit of it takes ~40 ms)."""
    document: dict[str, Any] = json.loads(EXAMPLE.read_text())
    document["samples"] = document["samples"][:15]
    return document


def with_rig_uncertainty(document: dict[str, Any], folder: Path) -> dict[str, Any]:
    """The dataset with each sample's raw pixel centres and a `rig_uncertainty` block (a
    stereo rig and its calibration covariance), as the stereo_target method writes it."""
    import cv2

    from hostpc.vision import StereoRig
    from hostpc.vision.rig_uncertainty import N_RIG, uncertainty_document
    from hostpc.vision.triangulation import project

    K = np.array([[1400.0, 0.0, 640.0], [0.0, 1401.0, 512.0], [0.0, 0.0, 1.0]])
    R = cv2.Rodrigues(np.array([0.001, -0.004, 0.002]))[0]
    rig = StereoRig((1280, 1024), K, [-0.08, 0.05, 4e-4, -3e-4, 0.0], K,
                    [-0.07, 0.04, 0.0, 0.0, 0.0], R, [-0.12, 1e-4, 5e-4])
    path = folder / "plain.json"
    path.write_text(json.dumps(document))
    points = load_dataset(path).samples.p
    for sample, x in zip(document["samples"], points, strict=True):
        sample["uv"] = [project(rig.K_left, rig.dist_left, x[None])[0].tolist(),
                        project(rig.K_right, rig.dist_right, (rig.R @ x + rig.T)[None])[0]
                        .tolist()]
    covariance = np.diag(np.linspace(1e-6, 1e-4, N_RIG))
    return {**document, "rig_uncertainty": uncertainty_document(rig, covariance)}


def feed(kind: str, count: int, base_text: bytes, document: Any, folder: Path,
         command: Any, allowed: set[int]) -> list[str]:
    """Write `count` mutated files of one kind, run `command(path, index)` on each; the
    broken contracts, each naming the input's index."""
    rng = np.random.default_rng((SEED, list(COUNTS).index(kind)))
    failures = []
    for index in range(count):
        if kind == "csv":
            data = mutate_csv(base_text.decode(), rng)
        elif kind == "urdf" and rng.random() < 0.6:
            data = mutate_urdf(base_text.decode(), rng)
        else:
            data = mutate(document, base_text, rng)
        path = folder / f"{kind}-{index}{'.urdf' if kind == 'urdf' else ''}"
        path.write_bytes(data)
        why = problem(run_cli(command(path, index)), allowed)
        if why is not None:
            failures.append(f"{kind} #{index}: {why}")
    return failures


def counts(kind: str) -> list[Any]:
    return [pytest.param(COUNTS[kind], id="default"),
            pytest.param(COUNTS[kind] * SLOW_FACTOR, id="slow", marks=pytest.mark.slow)]


@pytest.mark.parametrize("count", counts("dataset"))
def test_mutated_datasets_fit_or_one_line(tmp_path: Path, count: int) -> None:
    document = small_example()
    failures = feed("dataset", count, json.dumps(document).encode(), document, tmp_path,
                    lambda path, _: ["fit", str(path), "--cv-folds", "0", "--json"], {0, 1, 2})
    assert not failures, "\n".join(failures)


@pytest.mark.parametrize("count", counts("rig_dataset"))
def test_mutated_rig_uncertainty_blocks_fit_or_one_line(tmp_path: Path, count: int) -> None:
    """Most of the document is the block (24 x 24 covariance, the rig): most damage is."""
    document = with_rig_uncertainty(small_example(), tmp_path)
    base = tmp_path / "base.json"
    base.write_text(json.dumps(document))
    assert problem(run_cli(["fit", str(base), "--json"]), {0}) is None

    def command(path: Path, _: int) -> list[str]:
        return ["fit", str(path), "--cv-folds", "0", "--json"]

    failures = feed("rig_dataset", count, json.dumps(document).encode(), document,
                    tmp_path, command, {0, 1, 2})
    assert not failures, "\n".join(failures)


@pytest.mark.parametrize("count", counts("csv"))
def test_mutated_csv_imports_or_one_line(tmp_path: Path, count: int) -> None:
    def command(path: Path, index: int) -> list[str]:
        return ["import", str(path), "--method", "world_pose", "--robot", "ur10e",
                "--columns", COLUMNS, "-o", str(tmp_path / f"out-{index}.json")]

    failures = feed("csv", count, CSV_FILE.read_bytes(), None, tmp_path, command, {0, 2})
    assert not failures, "\n".join(failures)


@pytest.mark.parametrize("count", counts("urdf"))
def test_mutated_urdf_reads_or_one_line(tmp_path: Path, count: int) -> None:
    def command(path: Path, _: int) -> list[str]:
        return ["robots", "--robot", str(path), "--base-link", "base_link", "--tip-link",
                "tool0", "--json"]

    failures = feed("urdf", count, URDF_FILE.read_bytes(), None, tmp_path, command, {0, 2})
    assert not failures, "\n".join(failures)


@pytest.mark.parametrize("count", counts("plugin"))
def test_mutated_plugins_load_or_one_line(tmp_path: Path, count: int) -> None:
    dataset = tmp_path / "small.json"
    dataset.write_text(json.dumps(small_example()))

    def command(path: Path, _: int) -> list[str]:
        plugin = path.with_suffix(".py")
        path.rename(plugin)
        return ["fit", str(dataset), "--cv-folds", "0", "--plugin", str(plugin)]

    failures = feed("plugin", count, PLUGIN_FILE.read_bytes(), None, tmp_path, command,
                    {0, 1, 2})
    assert not failures, "\n".join(failures)


@pytest.fixture(scope="module")
def controller(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Any]:
    """A controller-stub (subprocess, 127.0.0.1) of the default simulated UR5e."""
    from hostpc.robots.simulator import SimulatedController, default_sim_scenario

    with SimulatedController(default_sim_scenario(), tmp_path_factory.mktemp("stub")) as sim:
        yield sim


def _expected_corrections(text: bytes, joints: int) -> np.ndarray | None:
    """What a push of this file adds to the controller's offsets (rad): each free joint
    offset's value, 0 for a held one, read the plain way; None if it is not JSON."""
    try:
        parameters = json.loads(text)["parameters"]
        return np.array([0.0 if parameters[f"joint_offsets.q{j + 1}"]["fixed"] is True
                         else float(parameters[f"joint_offsets.q{j + 1}"]["value"])
                         for j in range(joints)])
    except (ValueError, KeyError, TypeError, IndexError):
        return None


@pytest.mark.parametrize("count", counts("fit"))
def test_mutated_fit_files_are_refused_or_pushed_exactly(
        tmp_path: Path, controller: Any, count: int, monkeypatch: pytest.MonkeyPatch) -> None:
    """Every mutated FIT.json through `hostpc push` (a dry run; one in five for real):
    refused in one line, or planned; a real push leaves the controller holding exactly the
    file's corrections, a refused one leaves it untouched."""
    monkeypatch.setenv("ZEROCAL_TOKEN", controller.token)
    dataset = tmp_path / "small.json"
    dataset.write_text(json.dumps(small_example()))
    fitted = run_cli(["fit", str(dataset), "--cv-folds", "0", "--json"])
    assert isinstance(fitted, Outcome) and fitted.code == 0, fitted
    document = json.loads(fitted.out)
    address = f"{controller.address.host}:{controller.address.port}"
    base = tmp_path / "fit.json"
    base.write_text(fitted.out)
    assert problem(run_cli(["push", str(base), "--robot", address, "--dry-run"]), {0}) is None
    rng = np.random.default_rng((SEED, list(COUNTS).index("fit")))
    failures, pushed = [], 0
    for index in range(count):
        data = mutate(document, fitted.out.encode(), rng)
        path = tmp_path / f"fit-{index}.json"
        path.write_bytes(data)
        real = index % 5 == 0
        before = np.asarray(controller.truth()["zero_offsets"], float)
        argv = ["push", str(path), "--robot", address, "--out", str(tmp_path / f"push-{index}")]
        outcome = run_cli(argv if real else [*argv, "--dry-run"])
        why = problem(outcome, {0, 2, 5})
        if why is None and real:
            after = np.asarray(controller.truth()["zero_offsets"], float)
            assert isinstance(outcome, Outcome)
            expected = (_expected_corrections(data, before.size) if outcome.code == 0
                        else np.zeros(before.size))
            pushed += outcome.code == 0
            if expected is None or not np.allclose(after - before, expected, rtol=0,
                                                   atol=1e-12):
                why = (f"exit {outcome.code}: the controller moved by {after - before}, "
                       f"the file says {expected}")
            elif outcome.code == 0:  # undo it: the stub refuses offsets 5 deg from its own
                undo = run_cli(["rollback", "--run", str(tmp_path / f"push-{index}")])
                restored = np.asarray(controller.truth()["zero_offsets"], float)
                if problem(undo, {0}) is not None or not np.allclose(restored, before,
                                                                     rtol=0, atol=1e-12):
                    why = f"the rollback failed: {undo}"
        if why is not None:
            failures.append(f"fit #{index}: {why}")
    assert not failures, "\n".join(failures)
    assert pushed > 0  # some damage leaves a valid fit (e.g. a description): pushed exactly
