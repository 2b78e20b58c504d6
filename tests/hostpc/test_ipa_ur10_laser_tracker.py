"""Real data: Fraunhofer IPA's UR10 laser-tracker set (tests/data/README.md), 2773 random
poses of one UR10 (CB3) measured by a Leica laser tracker with a T-Mac 6-DoF probe on the
flange, through `hostpc import`, every built-in fit level and the pose-grouped held-out
table (docs/real-data.md).

The file is the tracker software's export as published: fields separated by ';', decimal
commas, the probe's orientation as intrinsic X-Y-Z Euler angles in degrees, positions in mm,
the hall temperature per row; the robot is UR's published UR10 DH table
(tests/data/ur10_dh.json).
"""

from __future__ import annotations

from pathlib import Path

import pytest

import hostpc
from tests.hostpc.realdata import DATA, check_every_level, import_csv

CSV = DATA / "ipa_ur10_laser_tracker_random_poses.csv"
COLUMNS = ("q=shoulder_pan_joint:wrist_3_joint,x=measurement_x,y=measurement_y,"
           "z=measurement_z,e1=measurement_rx,e2=measurement_ry,e3=measurement_rz,"
           "temperature=measurement_temperature")
IMPORT = ["--method", "world_pose", "--robot", str(DATA / "ur10_dh.json"),
          "--euler", "xyz-intrinsic", "--length-unit", "mm", "--angle-unit", "deg",
          "--sigma", "0.1", "--sigma-angle", "0.01", "--columns", COLUMNS]


@pytest.fixture(scope="module")
def ur10(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("ipa") / "ur10.json"
    return import_csv(CSV, out, *IMPORT)


def test_ur10_imports_every_row_of_the_tracker_export(ur10: Path) -> None:
    data = hostpc.load_dataset(ur10)
    assert len(data.samples.q) == 2773  # one pose per row, over 1000 poses of one robot
    temperature = data.samples.temperature
    assert temperature is not None and temperature[0] == pytest.approx(21.68)
    # decimal commas read as such: the first row's tracker position, mm -> m
    assert data.samples.p is not None
    first = data.samples.p[0]
    assert first.tolist() == pytest.approx([0.38397123, -3.2407562, 0.20172621])


@pytest.mark.slow
def test_ur10_converges_at_every_level(ur10: Path) -> None:
    fits = check_every_level(ur10, ["world", "tool"])
    held = {d.fixed for d in fits["offsets"].unidentifiable}
    assert {"joint_offsets.q1", "joint_offsets.q6"} <= held
    # pose-grouped held-out position error (docs/real-data.md): here every level gains
    # beyond one standard error, so auto takes the largest model
    table = fits["table"]
    assert table["nominal"]["cv_rms"] == pytest.approx(0.9906e-3, rel=0.01)
    assert table["offsets"]["cv_rms"] == pytest.approx(0.5514e-3, rel=0.01)
    assert table["offsets + geometry"]["cv_rms"] == pytest.approx(0.4907e-3, rel=0.01)
    assert table["auto"]["cv_rms"] < table["offsets + geometry"]["cv_rms"]
