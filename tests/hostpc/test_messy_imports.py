"""Messy real exports through `hostpc import` (a metrology engineer's files, built here from
the committed FIGAROH TALOS set, tests/data/README.md): joint columns in another order than
the robot's, instrument axes swapped, a last line cut short. Each is caught at import with
one line naming what to do, never read silently into a wrong dataset."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

import hostpc
from hostpc.cli.main import main
from tests.hostpc.realdata import DATA

CSV = DATA / "figaroh_talos_left_arm_mocap.csv"
TALOS = ["--method", "world_point", "--robot", str(DATA / "talos_left_arm.urdf"),
         "--base-link", "base_link", "--tip-link", "arm_left_7_link", "--sigma", "0.001"]
COLUMNS = "q=torso_1_joint:arm_left_7_joint,x=x1,y=y1,z=z1,t=t"


def _rows() -> list[list[str]]:
    with CSV.open(newline="") as stream:
        return list(csv.reader(stream))


def _write(path: Path, rows: list[list[str]]) -> Path:
    with path.open("w", newline="") as stream:
        csv.writer(stream).writerows(rows)
    return path


def _import(capsys: pytest.CaptureFixture[str], source: Path, out: Path,
            columns: str = COLUMNS) -> tuple[int, str, str]:
    capsys.readouterr()
    code = main(["import", str(source), *TALOS, "--columns", columns, "-o", str(out)])
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def _swapped_joint_columns(path: Path) -> Path:
    """The TALOS export with the columns arm_left_1_joint and arm_left_2_joint swapped, each
    keeping its header name (another export's column order)."""
    rows = _rows()
    i, j = rows[0].index("arm_left_1_joint"), rows[0].index("arm_left_2_joint")
    order = list(range(len(rows[0])))
    order[i], order[j] = j, i
    return _write(path, [[row[k] for k in order] for row in rows])


def test_a_joint_range_in_another_order_is_read_by_the_joint_names(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code, _, _ = _import(capsys, CSV, tmp_path / "talos.json")
    assert code == 0
    code, out, _ = _import(capsys, _swapped_joint_columns(tmp_path / "swap.csv"),
                           tmp_path / "swap.json")
    assert code == 0
    note = [line for line in out.splitlines() if line.startswith("note:")]
    assert len(note) == 1 and "q3=arm_left_1_joint" in note[0], out
    same = hostpc.load_dataset(tmp_path / "talos.json").samples
    swapped = hostpc.load_dataset(tmp_path / "swap.json").samples
    np.testing.assert_array_equal(swapped.q, same.q)


def test_joint_names_out_of_place_among_other_columns_are_refused_with_the_mapping(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    rows = _swapped_joint_columns(tmp_path / "swap.csv")
    # the range starts at z1: neither by position nor by name is a safe reading
    code, _, err = _import(capsys, rows, tmp_path / "bad.json",
                           "q=z1:arm_left_6_joint,x=x1,y=y1,z=z1")
    assert code == 2
    assert "q1=torso_1_joint,q2=torso_2_joint,q3=arm_left_1_joint" in err, err
    assert not (tmp_path / "bad.json").exists()


def test_headers_that_are_not_joint_names_keep_the_positional_range(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    rows = _rows()
    start = rows[0].index("torso_1_joint")
    rows[0][start:start + 9] = [f"J{k + 1}" for k in range(9)]
    code, out, _ = _import(capsys, _write(tmp_path / "j.csv", rows), tmp_path / "j.json",
                           "q=J1:J9,x=x1,y=y1,z=z1")
    assert code == 0 and "note:" not in out


def test_a_last_row_without_a_line_end_is_named(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    text = CSV.read_text()
    assert text.endswith("\n")
    cut = tmp_path / "cut.csv"
    cut.write_text(text.rstrip("\n")[:-3])  # copied while written: its last value cut short
    code, _, err = _import(capsys, cut, tmp_path / "cut.json")
    assert code == 0
    warned = [line for line in err.splitlines() if "no line end" in line]
    assert len(warned) == 1 and "row 62" in warned[0], err
    # the complete file says nothing of it
    code, _, err = _import(capsys, CSV, tmp_path / "whole.json")
    assert code == 0 and "no line end" not in err


def test_exchanged_instrument_axes_are_named_with_the_corrected_import(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    swapped = "q=torso_1_joint:arm_left_7_joint,x=x1,y=z1,z=y1,t=t"
    code, _, err = _import(capsys, CSV, tmp_path / "yz.json", swapped)
    assert code == 0
    warned = [line for line in err.splitlines() if "mirror image" in line]
    assert len(warned) == 1, err
    # as read the nominal robot misses the points by ~240 mm; exchanged, by 3.7 mm
    assert "with y and z exchanged by 3.69 mm" in warned[0]
    assert "--columns q=torso_1_joint:arm_left_7_joint,x=x1,y=y1,z=z1,t=t" in warned[0]
    # the fit of the mirrored set names it too (not "check that the numbers are in m")
    capsys.readouterr()
    assert main(["fit", str(tmp_path / "yz.json"), "--cv-folds", "0"]) == 0
    out = capsys.readouterr().out
    assert "mirror image" in out and "y and z columns exchanged" in out
    # the mapping as the instrument wrote it: no warning
    code, _, err = _import(capsys, CSV, tmp_path / "ok.json")
    assert code == 0 and "mirror image" not in err
