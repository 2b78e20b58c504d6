"""What `hostpc diagnose --ladder` and `hostpc fit` import: no scipy (its array-API layer
alone costs ~0.2 s, more than the 120-pose ladder itself), no OpenCV, no matplotlib.

Each command runs in a fresh interpreter (the test process has scipy loaded already); the
modules are read from sys.modules when the command has finished. Not a timed test: the
import set is what start-up costs, and it is what this guards."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
HEAVY = ("scipy", "cv2", "matplotlib")
_CHILD = r"""
import contextlib, io, json, runpy, sys
sys.argv = ["hostpc", *json.loads(sys.argv[1])]
with contextlib.redirect_stdout(io.StringIO()):
    try:
        runpy.run_module("hostpc.cli.main", run_name="__main__")
    except SystemExit as exc:
        code = exc.code
print(json.dumps({"code": code, "modules": sorted(sys.modules)}))
"""


def imported_by(*args: str) -> tuple[int, list[str]]:
    done = subprocess.run([sys.executable, "-c", _CHILD, json.dumps(list(args))], cwd=ROOT,
                          capture_output=True, text=True, check=True, timeout=120)
    report = json.loads(done.stdout.strip().splitlines()[-1])
    return report["code"], report["modules"]


@pytest.mark.parametrize("args", [
    ("diagnose", "--ladder", "examples/ur5e_stereo.json"),  # a null space: the pivoted QR
    ("diagnose", "--ladder", "examples/ur5e_stereo_hidden_compliance.json"),
    ("fit", "examples/ur5e_stereo.json"),
])
def test_offline_commands_import_no_scipy(args: tuple[str, ...]) -> None:
    code, modules = imported_by(*args)
    assert code in (0, 1)  # 1: not adequate (the hidden-compliance example)
    heavy = [m for m in modules if m.split(".")[0] in HEAVY]
    assert not heavy, heavy[:5]


@pytest.mark.parametrize("example", ["ur5e_stereo.json", "ur5e_stereo_hidden_compliance.json",
                                     "ur5e_stereo_known_frames.json"])
def test_diagnose_of_a_well_formed_file_imports_no_pydantic(example: str) -> None:
    """A well-formed dataset passes the plain checks of hostpc.dataset.schema: pydantic and
    the dataset models (~0.1 s of start-up) are not imported (a broken file still gets the
    models' checks and messages: test_dataset_plain_checks.py)."""
    code, modules = imported_by("diagnose", "--ladder", f"examples/{example}")
    assert code in (0, 1)
    assert not [m for m in modules if m.split(".")[0] in ("pydantic", "pydantic_core")
                or m == "hostpc.dataset.schema_models"]


def test_diagnose_imports_no_other_command() -> None:
    """diagnose's parser takes its robot options from hostpc.cli.robot_options: the
    `hostpc robots` command's module (its chain tables, six dataclasses: ~2 % of the
    command's instructions) and `hostpc fit`'s dataset reading are not imported."""
    code, modules = imported_by("diagnose", "--ladder", "examples/ur5e_stereo.json")
    assert code in (0, 1)
    assert "hostpc.cli.robot_options" in modules
    assert "hostpc.cli.robots" not in modules
    # fit's own options and figures (an archive, a URDF to write, the jackknife, a robust
    # fit's kept samples): diagnose's parser shares fit's model options, not these
    fit_only = ("hostpc.cli.archive_options", "hostpc.cli.urdf_out",
                "hostpc.fitting.resampling", "hostpc.diagnostics.robust_kept")
    assert not [m for m in modules if m in fit_only]


@pytest.mark.parametrize("example", ["ur5e_stereo.json", "ur5e_stereo_hidden_compliance.json"])
def test_diagnose_imports_no_process_or_urdf_machinery(example: str) -> None:
    """Every command imports hostpc.robots.warm_stub (it may start a simulator before the
    command's imports); only `hostpc calibrate --robot sim` starts one, so subprocess (with
    threading, selectors and signal) is imported where a process is started. The URDF
    reader (xml.etree, two dataclasses) is imported only for a dataset whose robot is a
    URDF chain. Together ~1 % of the command's instructions."""
    code, modules = imported_by("diagnose", "--ladder", f"examples/{example}")
    assert code in (0, 1)
    unwanted = [m for m in modules if m in ("subprocess", "hostpc.kinematics.urdf")
                or m.startswith("xml.")]
    assert not unwanted, unwanted


def test_the_offline_parsers_import_no_robots_command() -> None:
    """fit's, diagnose's and predict's modules (what `hostpc` imports to build their
    parsers) take their robot options from hostpc.cli.robot_options and import the `hostpc
    robots` command's module only when a command runs (docs/architecture.md)."""
    code = ("import sys, hostpc.cli.fit, hostpc.cli.diagnose, hostpc.cli.predict; "
            "print('hostpc.cli.robots' in sys.modules)")
    done = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True,
                          text=True, check=True, timeout=120)
    assert done.stdout.strip() == "False"


def test_calibrate_against_the_simulator_imports_no_scipy(tmp_path: Path) -> None:
    """The main job: a whole `hostpc calibrate --robot sim` (plan, rig, fit, push, verify,
    report) runs without scipy (its verification power imported scipy.special: ~0.3 s of
    the command's start-up)."""
    code, modules = imported_by("calibrate", "--robot", "sim", "--out", str(tmp_path / "run"))
    assert code == 0
    assert not [m for m in modules if m.split(".")[0] in ("scipy", "matplotlib")]


def test_fit_of_a_dataset_with_a_shared_error_imports_no_scipy(tmp_path: Path) -> None:
    """A dual_loop dataset with its head camera's calibration (`rig_uncertainty`): the
    shared-error scale gate and the guard's chi2 run in the fit, without scipy (its
    saddlepoint tail imported scipy.stats and scipy.optimize: ~0.5 s)."""
    import numpy as np

    from hostpc.kinds.dual_loop.planning import plan_poses
    from tests.hostpc.test_head_camera_uncertainty import world_documents

    document, _ = world_documents(1, plan_poses(12, np.random.default_rng(3)), 0.3)
    assert "rig_uncertainty" in document
    path = tmp_path / "dual_loop.json"
    path.write_text(json.dumps(document))
    code, modules = imported_by("fit", str(path))
    assert code == 0
    # OpenCV is used here: the calibration's sensitivities re-triangulate the pixel centres
    heavy = [m for m in modules if m.split(".")[0] in ("scipy", "matplotlib")]
    assert not heavy, heavy[:5]


def test_predict_imports_no_scipy(tmp_path: Path) -> None:
    fitted = subprocess.run([sys.executable, "-m", "hostpc.cli.main", "fit",
                             "examples/ur5e_stereo.json", "--json"], cwd=ROOT,
                            capture_output=True, text=True, check=True, timeout=120)
    (tmp_path / "fit.json").write_text(fitted.stdout)
    code, modules = imported_by("predict", str(tmp_path / "fit.json"),
                                "examples/ur5e_stereo.json")
    assert code == 0
    heavy = [m for m in modules if m.split(".")[0] in HEAVY]
    assert not heavy, heavy[:5]
