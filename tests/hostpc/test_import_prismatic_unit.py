"""`hostpc import --prismatic-unit`: a prismatic joint's column has its own unit (issue 25,
review item 2). FIGAROH's TIAGo file with the markers written in mm and the torso lift
left in m: `--length-unit mm` alone reads the lift in mm as well (the default, kept) and
warns that it spans under 1 mm, naming the option; `--prismatic-unit m` reads it right."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

import hostpc
from hostpc.cli.main import main
from tests.hostpc.test_figaroh_tiago import COLUMNS, CSV, ROBOT


@pytest.fixture(scope="module")
def markers_in_mm(tmp_path_factory: pytest.TempPathFactory) -> Path:
    rows = list(csv.reader(CSV.open(newline="")))
    lengths = [k for k, name in enumerate(rows[0]) if name[0] in "xyz"]
    out = tmp_path_factory.mktemp("mm") / "tiago_mm.csv"
    with out.open("w", newline="") as stream:
        writer = csv.writer(stream)
        writer.writerow(rows[0])
        for row in rows[1:]:
            writer.writerow([repr(float(v) * 1000) if k in lengths else v
                             for k, v in enumerate(row)])
    return out


def _import(source: Path, out: Path, *options: str) -> int:
    return main(["import", str(source), "--method", "world_point", *ROBOT, "--sigma",
                 "0.001", "--columns", COLUMNS, "-o", str(out), *options])


def test_the_lift_in_m_beside_markers_in_mm(markers_in_mm: Path, tmp_path: Path,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    assert _import(CSV, tmp_path / "si.json") == 0
    lift = hostpc.load_dataset(tmp_path / "si.json").samples.q[:, 0]
    assert np.ptp(lift) > 0.01  # the real lift travels centimetres
    capsys.readouterr()
    assert _import(markers_in_mm, tmp_path / "mixed.json", "--length-unit", "mm") == 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("warning: prismatic joint q1 spans only")
    assert "--prismatic-unit" in err[0] and "read in mm" in err[0]
    assert _import(markers_in_mm, tmp_path / "right.json", "--length-unit", "mm",
                   "--prismatic-unit", "m") == 0
    assert capsys.readouterr().err == ""
    right = hostpc.load_dataset(tmp_path / "right.json")
    assert np.allclose(right.samples.q[:, 0], lift, rtol=0, atol=1e-12)
    assert _import(markers_in_mm, tmp_path / "bad.json", "--prismatic-unit", "deg") == 2
