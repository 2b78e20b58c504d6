"""`hostpc push FIT.json`: an offline fit's offsets pushed with calibrate's guard rails,
journal and rollback, against the simulated controller (subprocess, loopback)."""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import numpy as np
import pytest

from hostpc.fitting import fit
from hostpc.robots.simulator import SimulatedController
from hostpc.synthesize import random_truth, synthesize_stereo_target
from tests.integration.test_calibrate_sim import TOKEN, run_cli, sim_scenario


def _offsets(sim: SimulatedController) -> np.ndarray:
    return np.asarray(sim.truth()["zero_offsets"], float)


@pytest.fixture(scope="module")
def fit_file(tmp_path_factory, stereo_poses) -> tuple[Path, dict[str, float]]:
    """A noise-free offline fit with free frames: q1 and q6 are held (unidentifiable)."""
    truth = random_truth(np.random.default_rng(5))
    data = synthesize_stereo_target(truth, q=stereo_poses, noise_scale=0.0)
    result = fit(data.dataset, cv_folds=0)
    path = tmp_path_factory.mktemp("fit") / "fit.json"
    path.write_text(json.dumps(result.to_dict()))
    return path, {name: result.value(name) for name in result.names}


def test_push_offline_fit_guard_rail_dry_run_push_and_rollback(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], fit_file) -> None:
    path, fitted = fit_file
    with SimulatedController(sim_scenario(), tmp_path / "stub") as sim:
        address = f"{sim.address.host}:{sim.address.port}"
        before = _offsets(sim)
        out = tmp_path / "push"
        # guard rail: a correction above the limit refuses the whole push (exit 5, as calibrate)
        code, stdout, stderr = run_cli(capsys, "push", str(path), "--robot", address,
                                       "--token", TOKEN, "--max-correction", "0.01",
                                       "--out", str(out))
        assert code == 5 and "exceeds the limit of 0.01 deg" in stderr
        assert np.array_equal(_offsets(sim), before) and not out.exists()
        # dry run: the plan, nothing written
        code, stdout, stderr = run_cli(capsys, "push", str(path), "--robot", address,
                                       "--token", TOKEN, "--dry-run", "--json")
        assert code == 0, stderr
        plan = json.loads(stdout)
        assert plan["status"] == "planned" and np.array_equal(_offsets(sim), before)
        # push: q2..q5 move by the fitted offsets, the held q1 and q6 stay
        code, stdout, stderr = run_cli(capsys, "push", str(path), "--robot", address,
                                       "--token", TOKEN, "--out", str(out))
        assert code == 0, stderr
        assert "hostpc rollback --run" in stdout
        after = _offsets(sim)
        for j in range(6):
            expected = fitted[f"joint_offsets.q{j + 1}"] if j in (1, 2, 3, 4) else 0.0
            assert after[j] - before[j] == pytest.approx(expected, abs=1e-12), j
        assert "unidentifiable" in stdout
        push = json.loads((out / "push.json").read_text())
        assert push["status"] == "pushed" and push["previous_offsets"] == before.tolist()
        assert [e["event"] for e in map(json.loads, (out / "journal.jsonl").read_text()
                                        .splitlines())] == ["push_intent", "push_written", "push"]
        # the same fit again: the ledger beside the fit says this controller carries it
        code, stdout, stderr = run_cli(capsys, "push", str(path), "--robot", address,
                                       "--token", TOKEN, "--out", str(tmp_path / "again"))
        assert code == 5 and "already carries this fit" in stderr, stderr
        assert len([line for line in stderr.strip().splitlines() if "warning" not in line]) == 1
        assert np.array_equal(_offsets(sim), after) and not (tmp_path / "again").exists()
        ledger = [json.loads(line) for line in
                  Path(str(path) + ".pushes.jsonl").read_text().splitlines()]
        assert ledger[-1]["controller"] == address and ledger[-1]["before"] == before.tolist()
        # rollback by the push folder, as for a calibration run
        code, stdout, stderr = run_cli(capsys, "rollback", "--run", str(out), "--token", TOKEN)
        assert code == 0, stderr
        assert np.array_equal(_offsets(sim), before)
        assert math.isfinite(after[1])
        # rolled back, the fit may be pushed again (a dry run is enough to show it)
        code, stdout, stderr = run_cli(capsys, "push", str(path), "--robot", address,
                                       "--token", TOKEN, "--dry-run")
        assert code == 0, stderr


def test_push_refuses_a_fit_of_another_robot(tmp_path: Path, capsys, fit_file) -> None:
    path, _ = fit_file
    document = json.loads(path.read_text())
    assert document["robot"]  # the fit records its dataset's robot
    document["robot"] = "some_other_robot"
    other = tmp_path / "other.json"
    other.write_text(json.dumps(document))
    with SimulatedController(sim_scenario(), tmp_path / "stub") as sim:
        address = f"{sim.address.host}:{sim.address.port}"
        before = _offsets(sim)
        code, _, stderr = run_cli(capsys, "push", str(other), "--robot", address,
                                  "--token", TOKEN, "--out", str(tmp_path / "p"))
        assert code == 5 and "measured on a some_other_robot" in stderr, stderr
        assert len([line for line in stderr.strip().splitlines() if "warning" not in line]) == 1
        assert np.array_equal(_offsets(sim), before)
        code, _, stderr = run_cli(capsys, "push", str(other), "--robot", address,
                                  "--token", TOKEN, "--dry-run", "--force")
        assert code == 0, stderr


def test_push_refuses_a_fit_with_another_joint_count(tmp_path: Path, capsys, fit_file) -> None:
    """Even with --force: 7 joint offsets cannot go to a 6-joint controller (exit 2)."""
    path, _ = fit_file
    document = json.loads(path.read_text())
    document["robot"] = None  # a URDF robot's fit names none: the count is all there is
    document["parameters"]["joint_offsets.q7"] = {"value": 1e-3, "std": 1e-4, "unit": "rad",
                                                  "fixed": False}
    document["n_parameters"] += 1
    other = tmp_path / "seven.json"
    other.write_text(json.dumps(document))
    with SimulatedController(sim_scenario(), tmp_path / "stub") as sim:
        address = f"{sim.address.host}:{sim.address.port}"
        before = _offsets(sim)
        code, _, stderr = run_cli(capsys, "push", str(other), "--robot", address,
                                  "--token", TOKEN, "--force", "--out", str(tmp_path / "p"))
        assert code == 2, stderr
        assert f"the fit has 7 joint offsets, the controller at {address} has 6" in stderr
        assert np.array_equal(_offsets(sim), before) and not (tmp_path / "p").exists()


@pytest.mark.parametrize(("content", "message"), [
    ("{", "not valid JSON"),
    ('{"parameters": {}}', "no 'converged'"),
    ('{"parameters": {"tool.x": {"value": 0.1, "fixed": false}}, "converged": true, '
     '"chi2": 1, "dof": 3}', "no joint_offsets"),
    ('{"parameters": {"joint_offsets.q1": {"value": "x"}}, "converged": true, "chi2": 1,'
     ' "dof": 3}', "joint_offsets.q1.value"),
])
def test_bad_fit_file_is_one_line(tmp_path, capsys, content, message) -> None:
    path = tmp_path / "fit.json"
    path.write_text(content)
    code, _, stderr = run_cli(capsys, "push", str(path), "--robot", "127.0.0.1:1")
    assert code == 2 and message in stderr and len(stderr.strip().splitlines()) == 1


def _figaroh_poses(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> Path:
    """FIGAROH's UR10e poses (metres) imported as a world_pose dataset (units.length m)."""
    data = Path(__file__).resolve().parents[1] / "data" / "figaroh_ur10e_calibration.csv"
    dataset = tmp_path / "poses.json"
    code, _, stderr = run_cli(capsys, "import", str(data), "--method", "world_pose",
                              "--robot", "ur10e", "--no-guess", "--columns",
                              "q=shoulder_pan_joint:wrist_3_joint,x=x1,y=y1,z=z1,roll=phix1,"
                              "pitch=phiy1,yaw=phiz1", "-o", str(dataset))
    assert code == 0, stderr
    return dataset


def test_a_fit_that_did_not_converge_says_why_and_push_refuses_it(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """FIGAROH's UR10e poses (metres) in a dataset that says `units.length: mm`: the fit
    does not converge; its text says so with the units hint (the residuals are about 1e4
    times the stated noise) and the next command, exit 0 (non-convergence is reported,
    never raised: docs/fitting.md); `hostpc push` of its --json refuses it as not
    converged, naming the dataset to diagnose, before anything reaches the controller
    (before: "converged: NO" alone, and push said only what its guard rails say of any fit)."""
    dataset = _figaroh_poses(tmp_path, capsys)
    document = json.loads(dataset.read_text())
    document["units"]["length"] = "mm"
    dataset.write_text(json.dumps(document))
    code, stdout, stderr = run_cli(capsys, "fit", str(dataset), "--cv-folds", "0")
    assert code == 0, stderr
    line = stdout.splitlines()[1]
    assert line.startswith("  converged: NO (") and "the values below are not a fit" in line
    # the hint names the declared unit and what the numbers' scale says (before: "e.g.
    # units.length mm for numbers in metres", to a file that declares mm already)
    assert re.search(r"times the stated noise: units.length is mm, but the positions span "
                     r"\d\.\d+-\d\.\d+: metres\? set units.length m; next", line), line
    assert line.endswith(f"next: hostpc diagnose {dataset} --ladder"), line
    code, stdout, stderr = run_cli(capsys, "fit", str(dataset), "--cv-folds", "0", "--json")
    assert code == 0 and json.loads(stdout)["converged"] is False, stderr
    fit_path = tmp_path / "fit.json"
    fit_path.write_text(stdout)
    with SimulatedController(sim_scenario(), tmp_path / "stub") as sim:
        before = _offsets(sim)
        code, stdout, stderr = run_cli(capsys, "push", str(fit_path), "--robot",
                                       f"{sim.address.host}:{sim.address.port}",
                                       "--token", TOKEN, "--dry-run")
        assert code == 5 and stdout == "", stderr
        assert stderr.strip().splitlines()[-1] == (
            f"hostpc push: error: push refused: {fit_path}: the fit did not converge "
            "(maximum iterations reached): its values are not a fit; find why with "
            f"`hostpc diagnose {dataset} --ladder` (do the dataset's `units` match its "
            "numbers?), fit again, then push (--force to push anyway)")
        assert np.array_equal(_offsets(sim), before)


def test_the_units_hint_asks_to_check_a_unit_the_numbers_do_not_contradict(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """FIGAROH's UR10e poses declared in metres, as they are: the hint's facts name the
    declared unit and the positions' span, and suggest no other unit (nothing says one)."""
    from hostpc.cli.units_hint import declared_length_unit, length_unit_hint
    from hostpc.dataset import load_dataset

    dataset = _figaroh_poses(tmp_path, capsys)
    assert declared_length_unit(dataset) == "m"
    hint = length_unit_hint(load_dataset(dataset), "m")
    assert re.fullmatch(r"units.length is m: check that the numbers are in m \(the positions "
                        r"span 1\.4\d-1\.8\d\)", hint), hint


def test_a_run_folders_fit_pushed_after_the_runs_own_push_is_refused(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], fit_file) -> None:
    """`calibrate` pushes r1's correction; `fit r1/dataset.json --json > f.json` then
    `push f.json` (and a push of r1's own fit.json) would add it again: FIT.json records
    the offsets r1 measured under, and the push refuses (exit 5, one line, nothing written)
    because the controller holds them plus the fit's corrections. Rolled back, the
    controller holds the measured-under offsets again and the fit may be pushed. A fit of a
    dataset outside a run folder says it cannot check this."""
    from tests.integration.test_calibrate_sim import truth_rig_file

    rig = truth_rig_file(sim_scenario(), tmp_path / "rig.json")
    run = tmp_path / "r1"
    with SimulatedController(sim_scenario(), tmp_path / "stub") as sim:
        address = f"{sim.address.host}:{sim.address.port}"
        before = _offsets(sim)
        code, _, stderr = run_cli(
            capsys, "calibrate", "--robot", address, "--token", TOKEN, "--rig", str(rig),
            "--known", "target", "--poses", "16", "--verify-poses", "0", "--no-report",
            "--out", str(run))
        assert code == 0, stderr
        pushed = _offsets(sim)
        assert not np.array_equal(pushed, before)
        code, stdout, stderr = run_cli(capsys, "fit", str(run / "dataset.json"), "--json")
        assert code == 0, stderr
        document = json.loads(stdout)
        assert document["measured_under"] == {"run": str(run.resolve()),
                                              "dataset": "dataset.json",
                                              "zero_offsets": before.tolist()}
        refit = tmp_path / "elsewhere" / "f.json"
        refit.parent.mkdir()
        refit.write_text(stdout)
        for fit_path in (refit, run / "fit.json"):
            code, stdout, stderr = run_cli(capsys, "push", str(fit_path), "--robot", address,
                                           "--token", TOKEN, "--out", str(tmp_path / "p"))
            assert code == 5, stderr
            (line,) = [text for text in stderr.strip().splitlines() if "warning" not in text]
            assert "already carries this fit's corrections" in line, line
            assert f"hostpc rollback --run {run.resolve()}" in line, line
            assert np.array_equal(_offsets(sim), pushed) and not (tmp_path / "p").exists()
        code, _, stderr = run_cli(capsys, "rollback", "--run", str(run), "--token", TOKEN)
        assert code == 0, stderr
        code, stdout, stderr = run_cli(capsys, "push", str(refit), "--robot", address,
                                       "--token", TOKEN, "--dry-run")
        assert code == 0, stderr
        assert "not checked" not in stdout
        # a fit from outside a run folder: the push says it cannot check, in one line
        path, _ = fit_file
        code, stdout, stderr = run_cli(capsys, "push", str(path), "--robot", address,
                                       "--token", TOKEN, "--dry-run")
        assert code == 0, stderr
        assert len([text for text in stdout.splitlines() if text.startswith("not checked:")]
                   ) == 1, stdout
