"""Every file hostpc reads goes through hostpc.input_files: a FIFO, a device or a directory
is refused in one line before anything is read (a FIFO used to hang fit, diagnose, push,
robots and import forever), each kind has a size limit, and the damaged blocks and URDF
origins that used to pass (rig_uncertainty) or give a traceback (1e200 m) are refused."""

from __future__ import annotations

import json
import os
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from hostpc.cli.main import main
from hostpc.input_files import CSV, DATASET, FIT, PLUGIN, URDF, InputKind, read_input_bytes

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "examples" / "ur5e_stereo.json"
URDF_FILE = ROOT / "tests" / "data" / "arm7_prismatic.urdf"
CSV_FILE = ROOT / "tests" / "data" / "figaroh_ur10e_calibration.csv"
PLUGIN_FILE = Path(__file__).with_name("distance_sensor_plugin.py")
COLUMNS = "q=shoulder_pan_joint:wrist_3_joint,x=x1,y=y1,z=z1,roll=phix1,pitch=phiy1,yaw=phiz1"

COMMANDS: dict[str, Callable[[str], list[str]]] = {
    "fit": lambda f: ["fit", f],
    "diagnose": lambda f: ["diagnose", f],
    "push": lambda f: ["push", f, "--robot", "127.0.0.1:1"],
    "robots": lambda f: ["robots", "--robot", f, "--base-link", "base_link",
                         "--tip-link", "tool0"],
    "import": lambda f: ["import", f, "--method", "world_pose", "--robot", "ur10e",
                         "--columns", COLUMNS, "-o", os.devnull + ".json"],
    "import --robot URDF": lambda f: ["import", str(CSV_FILE), "--method", "world_pose",
                                      "--robot", f, "--base-link", "base_link", "--tip-link",
                                      "tool0", "--columns", COLUMNS, "-o", "x.json"],
    "fit --plugin": lambda f: ["fit", str(EXAMPLE), "--plugin", f],
}


def one_line_exit_2(capsys: pytest.CaptureFixture[str], argv: list[str]) -> str:
    capsys.readouterr()
    started = time.monotonic()
    assert main(argv) == 2
    assert time.monotonic() - started < 10.0
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    return err


@pytest.mark.parametrize("command", list(COMMANDS))
def test_a_fifo_a_device_and_a_directory_are_refused_at_once(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], command: str) -> None:
    suffix = {"fit --plugin": ".py", "robots": ".urdf", "import --robot URDF": ".urdf"}.get(
        command, ".json")  # what the command recognises the file by
    fifo, zero, folder = (tmp_path / f"{name}{suffix}" for name in ("fifo", "zero", "folder"))
    os.mkfifo(fifo)  # no writer: opening it for reading would wait forever
    zero.symlink_to("/dev/zero")
    folder.mkdir()
    for path, what in ((fifo, "not a regular file (a FIFO)"),
                       (zero, "not a regular file (a device)"), (folder, "is a directory")):
        assert f"{path}: {what}" in one_line_exit_2(capsys, COMMANDS[command](str(path)))


@pytest.mark.parametrize(("kind", "command", "path"), [
    (DATASET, "fit", EXAMPLE), (URDF, "robots", URDF_FILE), (CSV, "import", CSV_FILE),
    (PLUGIN, "fit --plugin", PLUGIN_FILE),
])
def test_each_kind_has_a_size_limit_named_with_its_variable(
        capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, kind: InputKind,
        command: str, path: Path) -> None:
    monkeypatch.setenv(kind.env, "0.001")  # 1 kB: every test file is larger
    err = one_line_exit_2(capsys, COMMANDS[command](str(path)))
    assert f"above the {kind.name} size limit of 0.001 MB (set ${kind.env}" in err


def test_a_file_growing_past_the_limit_while_read_is_refused(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The size is checked on the open descriptor and again on what was read."""
    monkeypatch.setenv(FIT.env, "0.001")
    path = tmp_path / "fit.json"
    path.write_bytes(b" " * 500)
    assert read_input_bytes(path, FIT) == b" " * 500
    original = os.fstat
    with path.open("ab") as handle, monkeypatch.context() as patch:

        def grow(fd: int) -> os.stat_result:  # the file grows after the fstat
            status = original(fd)
            handle.write(b" " * 1000)
            handle.flush()
            return status

        patch.setattr(os, "fstat", grow)
        with pytest.raises(FIT.error, match="more than that, above the fit size limit"):
            read_input_bytes(path, FIT)


def test_a_bad_limit_is_one_line(capsys: pytest.CaptureFixture[str],
                                 monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(URDF.env, "-3")
    err = one_line_exit_2(capsys, COMMANDS["robots"](str(URDF_FILE)))
    assert "$ZEROCAL_MAX_URDF_MB='-3': expected a positive number of MB" in err


@pytest.mark.parametrize(("old", "new", "message"), [
    ('xyz="0 0 0.1"', 'xyz="1e200 0 0.1"', "origin xyz: '1e200 0 0.1' is outside the physical"
     " range (|value| <= 100 m)"),
    ('rpy="0 0 0"', 'rpy="0 0 1e9"', "origin rpy: '0 0 1e9' is outside"),
    ('xyz="0 0 1"', 'xyz="1e308 1e308 0"', "axis: '1e308 1e308 0' is too large"),
])
def test_urdf_values_out_of_range_are_one_line(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], old: str, new: str,
        message: str) -> None:
    text = URDF_FILE.read_text()
    assert old in text
    path = tmp_path / "arm.urdf"
    path.write_text(text.replace(old, new, 1))
    assert message in one_line_exit_2(capsys, COMMANDS["robots"](str(path)))


def _rig_document(tmp_path: Path) -> dict[str, Any]:
    from tests.hostpc.test_mutated_inputs import small_example, with_rig_uncertainty

    return with_rig_uncertainty(small_example(), tmp_path)


def _covariance(document: dict[str, Any]) -> list[list[float]]:
    rows: list[list[float]] = document["rig_uncertainty"]["covariance"]
    return rows


RIG_DAMAGE: list[tuple[Callable[[dict[str, Any]], None], str]] = [
    (lambda d: _covariance(d)[3].__setitem__(5, 1e-5), "covariance: not symmetric ([3][5]"),
    (lambda d: _covariance(d)[0].__setitem__(0, -1e-3), "covariance: not positive semi-definite"),
    (lambda d: _covariance(d)[2].__setitem__(2, "1e-4"),
     "covariance[2][2]: expected a finite number, got '1e-4'"),
    (lambda d: _covariance(d)[4].__setitem__(4, True), "covariance[4][4]: expected a finite"),
    (lambda d: _covariance(d).pop(), "covariance: expected a 24 x 24 array"),
    (lambda d: _covariance(d)[21].__setitem__(21, 1e6),
     "covariance[21][21]: standard deviation 1e+03 m is above the believable 10 m"),
    (lambda d: d["rig_uncertainty"]["parameters"].reverse(), "parameters: expected the 24"),
    (lambda d: d["rig_uncertainty"].pop("covariance"), "covariance: required field missing"),
    (lambda d: d["rig_uncertainty"]["rig"].__setitem__("T", [0, 0, 0]), "rig: T: zero baseline"),
    (lambda d: d["rig_uncertainty"].__setitem__("pixel_floor_px", "0.2"), "pixel_floor_px:"),
    (lambda d: d.__setitem__("rig_uncertainty", [1, 2]), "rig_uncertainty: expected an object"),
]


def test_damaged_rig_uncertainty_blocks_are_refused_on_load(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """They used to be accepted silently (skipped, or changing the push guard's chi2)."""
    base = _rig_document(tmp_path)
    path = tmp_path / "with_rig.json"
    path.write_text(json.dumps(base))
    assert main(["fit", str(path), "--cv-folds", "0"]) == 0
    for damage, message in RIG_DAMAGE:
        document = json.loads(json.dumps(base))
        damage(document)
        path.write_text(json.dumps(document))
        err = one_line_exit_2(capsys, ["fit", str(path)])
        assert f"{path}: rig_uncertainty" in err and message in err, (message, err)
    scaled = json.loads(json.dumps(base))
    scaled["rig_uncertainty"]["covariance"] = (
        np.asarray(_covariance(scaled)) * 4.0).tolist()  # a valid, larger covariance
    path.write_text(json.dumps(scaled))
    assert main(["fit", str(path), "--cv-folds", "0"]) == 0
