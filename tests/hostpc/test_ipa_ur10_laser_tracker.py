"""Real data: Fraunhofer IPA's UR10 laser-tracker set (tests/data/README.md), 2773 random
poses of one UR10 (CB3) measured by a Leica laser tracker with a T-Mac 6-DoF probe on the
flange, through `hostpc import`, every built-in fit level and the pose-grouped held-out
table (docs/real-data.md).

The file is the tracker software's export as published: fields separated by ';', decimal
commas, the probe's orientation as intrinsic X-Y-Z Euler angles in degrees, positions in mm,
the hall temperature per row; the robot is UR's published UR10 DH table
(tests/data/ur10_dh.json).

The file is not in this repository (tests/data/README.md says why and where to get it): the
tests of it read it from $ZEROCAL_IPA_UR10_CSV, else from the steering repository's
shared/data/ beside the repository, check its sha256, and skip when it is not there. The
import of that format is tested without it: a tracker export of the same columns is written
from the UR10 table's own kinematics with known joint offsets, imported and fitted.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import hostpc
from hostpc.kinematics import forward, pose_to_transform, rpy_to_matrix
from hostpc.kinematics.table_file import load_table_chain
from tests.hostpc.realdata import DATA, check_every_level, import_csv

NAME = "ipa_ur10_laser_tracker_random_poses.csv"
SHA256 = "904a1d195e558315bd21469abb02bfcc000dd1296c0cd68eb86c62e95f7ba160"
SHARED = Path(__file__).resolve().parents[2].parent / "shared" / "data" / NAME
ENV = "ZEROCAL_IPA_UR10_CSV"
JOINTS = ("shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint", "wrist_1_joint",
          "wrist_2_joint", "wrist_3_joint")
COLUMNS = ("q=shoulder_pan_joint:wrist_3_joint,x=measurement_x,y=measurement_y,"
           "z=measurement_z,e1=measurement_rx,e2=measurement_ry,e3=measurement_rz,"
           "temperature=measurement_temperature")
UNITS = ["--method", "world_pose", "--robot", str(DATA / "ur10_dh.json"),
         "--euler", "xyz-intrinsic", "--length-unit", "mm", "--angle-unit", "deg"]
IMPORT = [*UNITS, "--sigma", "0.1", "--sigma-angle", "0.01", "--columns", COLUMNS]


@pytest.fixture(scope="module")
def ipa_csv() -> Path:
    """The IPA file, its sha256 checked; the tests of it skip when it is not there."""
    given = os.environ.get(ENV)
    path = Path(given) if given else SHARED
    if not path.is_file():
        pytest.skip(f"IPA UR10 set not here: put {NAME} (sha256 {SHA256[:12]}.., "
                    f"tests/data/README.md) at {SHARED} or name it in ${ENV}")
    digest = hashlib.sha256(path.read_bytes()).hexdigest()
    assert digest == SHA256, f"{path}: sha256 {digest}, not the IPA file's {SHA256}"
    return path


@pytest.fixture(scope="module")
def ur10(ipa_csv: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("ipa") / "ur10.json"
    return import_csv(ipa_csv, out, *IMPORT)


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


OFFSETS_DEG = np.array([0.3, -0.12, 0.08, 0.15, -0.2, 0.25])  # injected, q_true = q + dq
WORLD = pose_to_transform([0.4, -3.2, 0.1], [0.02, -0.01, -1.6])  # robot base in tracker
TOOL = pose_to_transform([0.01, -0.02, 0.08], [0.0, 0.05, 0.3])  # probe on the flange


def _tracker_export(path: Path, n: int = 40) -> dict[str, np.ndarray]:
    """A tracker export in the IPA file's format (';', decimal commas, mm, intrinsic X-Y-Z
    Euler degrees, temperature, a standard deviation after each value, the commanded pose
    first and not read) of ``n`` poses of the UR10 table with OFFSETS_DEG injected, plus a
    clock-time Timestamp in Unix seconds (the IPA file's lost its digits). Each position
    carries noise of its own stated per-axis sigma. Returns the columns as written."""
    rng = np.random.default_rng(25)
    q = rng.uniform(-np.pi, np.pi, size=(n, 6))
    T = WORLD @ forward(load_table_chain(DATA / "ur10_dh.json"),
                        q + np.radians(OFFSETS_DEG)).T_base_flange @ TOOL
    std = rng.uniform(0.002, 0.02, size=(n, 3))  # mm
    xyz = T[:, :3, 3] * 1e3 + std * rng.standard_normal((n, 3))
    euler = Rotation.from_matrix(T[:, :3, :3]).as_euler("XYZ", degrees=True)
    columns = {"Timestamp": 1606832400.25 + 7.5 * np.arange(n),
               **{f"Goal {k}": np.zeros(n) for k in ("x", "y", "z", "roll", "pitch", "yaw")},
               **{joint: q[:, j] for j, joint in enumerate(JOINTS)},
               "measurement_temperature": np.linspace(21.68, 22.41, n)}
    for k, axis in enumerate("xyz"):
        columns[f"measurement_{axis}"], columns[f"measurement_std_{axis}"] = xyz[:, k], std[:, k]
    for k, axis in enumerate(("rx", "ry", "rz")):
        columns[f"measurement_{axis}"] = euler[:, k]
        columns[f"measurement_std_{axis}"] = np.full(n, 0.001)
    table = np.column_stack(list(columns.values()))
    lines = [";".join(columns)] + [";".join(repr(float(v)).replace(".", ",") for v in row)
                                   for row in table]
    path.write_text("\n".join(lines) + "\n")
    return columns


def test_a_tracker_export_of_the_ipa_format_imports_exactly_and_fits_its_offsets(
        tmp_path: Path) -> None:
    """Without the IPA file: its format written from known truth; the import reads every
    value (a decimal comma misread shifts a position by orders of magnitude), the per-axis
    sigma columns, the temperature and the clock time; a fit recovers the injected joint
    offsets of q2..q5 (q1 and q6 are the world's and the tool's z rotation: held)."""
    written = _tracker_export(tmp_path / "export.csv")
    columns = (COLUMNS + ",sx=measurement_std_x,sy=measurement_std_y,sz=measurement_std_z,"
               "t=Timestamp")
    dataset = import_csv(tmp_path / "export.csv", tmp_path / "export.json", *UNITS,
                         "--sigma-angle", "0.001", "--columns", columns)
    samples = hostpc.load_dataset(dataset).samples
    assert samples.n == 40 and samples.p is not None and samples.temperature is not None
    np.testing.assert_allclose(samples.q, np.column_stack([written[j] for j in JOINTS]),
                               rtol=1e-15, atol=0)
    xyz = np.column_stack([written[f"measurement_{a}"] for a in "xyz"]) * 1e-3
    np.testing.assert_allclose(samples.p, xyz, rtol=1e-15, atol=1e-15)
    sigma = np.column_stack([written[f"measurement_std_{a}"] for a in "xyz"]) * 1e-3
    variance = np.diagonal(samples.fields["pose_cov"], axis1=1, axis2=2)
    np.testing.assert_allclose(variance[:, :3], sigma**2, rtol=1e-12, atol=0)
    np.testing.assert_allclose(variance[:, 3:], np.radians(0.001) ** 2, rtol=1e-12, atol=0)
    euler = np.column_stack([written[f"measurement_{a}"] for a in ("rx", "ry", "rz")])
    np.testing.assert_allclose(rpy_to_matrix(samples.fields["rpy"]),
                               Rotation.from_euler("XYZ", euler, degrees=True).as_matrix(),
                               rtol=0, atol=1e-12)
    np.testing.assert_array_equal(samples.temperature, written["measurement_temperature"])
    assert samples.t is not None
    np.testing.assert_allclose(samples.t, 7.5 * np.arange(40), rtol=0, atol=1e-6)

    result = hostpc.fit(hostpc.load_dataset(dataset))
    assert result.converged, result.message
    held = {d.fixed for d in result.unidentifiable}
    assert {"joint_offsets.q1", "joint_offsets.q6"} <= held
    for j in (2, 3, 4, 5):
        estimate = result.parameters[f"joint_offsets.q{j}"]
        assert estimate.std is not None and not estimate.fixed
        error = abs(np.degrees(estimate.value) - OFFSETS_DEG[j - 1])
        assert error < 0.005 and error < 5 * np.degrees(estimate.std), (j, estimate)
