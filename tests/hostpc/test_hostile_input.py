"""Hostile and careless input to the offline commands: every bad dataset and option gets
exit code 2 and one line naming what is wrong; nothing reads without limit; no traceback,
no numpy warning (docs/security.md lists every row)."""

from __future__ import annotations

import copy
import json
import os
import time
from pathlib import Path
from typing import Any

import pytest

from hostpc.cli.main import main
from hostpc.dataset import dataset_from_dict
from hostpc.dataset.validation import MAX_DATASET_MB_ENV
from hostpc.errors import DatasetError

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "ur5e_stereo.json"
DUAL_LOOP = {
    "format": "zerocal-dataset/1", "method": "dual_loop", "robot": {"name": "humanoid_upper"},
    "frames": {"camera": {"xyz": [0, 0, 0], "rpy": [0, 0, 0]},
               "left_base": {"xyz": [0, 0, 0], "rpy": [0, 0, 0]},
               "right_base": {"xyz": [0, 0, 0], "rpy": [0, 0, 0]},
               "left_target": [0, 0, 0], "right_target": [0, 0, 0]},
    "samples": [{"chain": "left", "q_head": [0, 0], "q_arm": [0] * 7, "p": [0, 0, 0.5],
                 "sigma": 1e-4}],
}


def example() -> dict[str, Any]:
    document: dict[str, Any] = json.loads(EXAMPLE.read_text())
    return document


def one_line_exit_2(capsys: pytest.CaptureFixture[str], *argv: str) -> str:
    assert main(list(argv)) == 2
    captured = capsys.readouterr()
    assert captured.err.count("\n") == 1, captured.err
    assert "Traceback" not in captured.err and "Warning" not in captured.err
    return captured.err


def damaged(tmp_path: Path, change: Any, base: dict[str, Any] | None = None) -> Path:
    document = copy.deepcopy(base if base is not None else example())
    change(document)
    path = tmp_path / "damaged.json"
    path.write_text(json.dumps(document))
    return path


def set_in(path: tuple[Any, ...], value: Any) -> Any:
    def change(document: dict[str, Any]) -> None:
        target = document
        for key in path[:-1]:
            target = target[key]
        target[path[-1]] = value
    return change


DATASET_ROWS = [
    (("samples", 3, "p"), [1e160, 0.0, 0.4], "samples[3].p[0]: 1e+160 m is outside"),
    (("samples", 2, "q"), [0.1, 0.2, 1000.0, 0.0, 0.0, 0.0], "samples[2].q[2]: 1000 rad"),
    (("samples", 1, "cov"), [[1e-30, 0, 0], [0, 1e-30, 0], [0, 0, 1e-30]],
     "samples[1].cov: standard deviation 1e-15 m along a principal axis is below"),
    (("samples", 1, "cov"), [[1e6, 0, 0], [0, 1e6, 0], [0, 0, 1e6]],
     "samples[1].cov: standard deviation 1e+03 m along a principal axis is above"),
    (("frames", "tool", "xyz"), [0.0, 1e5, 0.0], "frames.tool.xyz[1]: 100000 m"),
    (("frames", "tool", "rpy"), [0.0, 0.0, 1e9], "frames.tool.rpy[2]: 1e+09 rad"),
    (("frames", "target"), [0.0, 0.0, -1e3], "frames.target[2]: -1000 m"),
    (("samples", 0, "t"), 1e300, "samples[0].t: 1e+300 s"),
]


@pytest.mark.parametrize(("where", "value", "message"), DATASET_ROWS)
@pytest.mark.parametrize("command", [["fit"], ["fit", "--json"], ["diagnose", "--json"]])
def test_values_outside_physical_ranges_are_refused_on_load(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], where: tuple[Any, ...], value: Any,
    message: str, command: list[str],
) -> None:
    path = damaged(tmp_path, set_in(where, value))
    err = one_line_exit_2(capsys, *command, str(path))
    assert str(path) in err and message in err, err


def test_a_dual_loop_dataset_with_an_unknown_robot_names_file_and_field(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = damaged(tmp_path, set_in(("robot", "name"), "robbie"), DUAL_LOOP)
    err = one_line_exit_2(capsys, "fit", str(path))
    assert f"{path}: robot.name: unknown kinematic tree 'robbie'" in err
    with pytest.raises(DatasetError, match="robot.name"):
        dataset_from_dict({**DUAL_LOOP, "robot": {"name": "robbie"}})


def test_a_device_is_refused_at_once(capsys: pytest.CaptureFixture[str]) -> None:
    started = time.monotonic()
    err = one_line_exit_2(capsys, "fit", "/dev/zero")
    assert "/dev/zero: not a regular file" in err
    assert time.monotonic() - started < 5.0  # nothing was read (it used to read 5 GB)


def test_files_above_the_size_limit_are_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv(MAX_DATASET_MB_ENV, "0.01")  # 10 kB; the example is larger
    err = one_line_exit_2(capsys, "fit", str(EXAMPLE))
    assert "above the dataset size limit of 0.01 MB" in err and MAX_DATASET_MB_ENV in err
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)  # no writer: opening it for reading used to wait forever
    started = time.monotonic()
    err = one_line_exit_2(capsys, "fit", str(fifo))
    assert f"{fifo}: not a regular file (a FIFO)" in err
    assert time.monotonic() - started < 5.0
    monkeypatch.setenv(MAX_DATASET_MB_ENV, "nan")
    assert "expected a positive number of MB" in one_line_exit_2(capsys, "fit", str(EXAMPLE))


@pytest.mark.parametrize(("argv", "message"), [
    (["fit", str(EXAMPLE), "--cv-folds", "1"], "--cv-folds: expected 0 or an integer from 2"),
    (["fit", str(EXAMPLE), "--cv-folds", "nan"], "--cv-folds: expected 0 or an integer"),
    (["diagnose", str(EXAMPLE), "--cv-folds", "-3"], "--cv-folds: expected 0 or an integer"),
    (["diagnose", str(EXAMPLE), "--alpha", "nan"], "alpha nan: must be between 0 and 1"),
    (["diagnose", str(EXAMPLE), "--alpha", "inf"], "alpha inf: must be between 0 and 1"),
    (["status", "--timeout", "nan"], "--timeout: expected a finite number > 0"),
    (["status", "--timeout", "inf"], "--timeout: expected a finite number > 0"),
    (["status", "--timeout", "-1"], "--timeout: expected a finite number > 0"),
    (["rollback", "--id", "rb-1", "--timeout", "0"], "--timeout: expected a finite number > 0"),
    (["status", "--robot", "127.0.0.1:"], "no port after ':'"),
    (["rollback", "--robot", "127.0.0.1:", "--id", "rb-1"], "no port after ':'"),
])
def test_bad_numeric_options_are_one_line_exit_2(
    capsys: pytest.CaptureFixture[str], argv: list[str], message: str
) -> None:
    assert message in one_line_exit_2(capsys, *argv)
