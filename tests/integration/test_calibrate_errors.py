"""`hostpc calibrate` on bad input: one line on stderr, the documented exit code, and
nothing lost or half-written."""

from __future__ import annotations

import json
import socket
from pathlib import Path

import pytest

from hostpc.robots.simulator import SimulatedController
from tests.integration.test_calibrate_sim import TOKEN, run_cli, sim_scenario, truth_rig_file


def _closed_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _error_line(stderr: str) -> str:
    lines = stderr.strip().splitlines()
    assert lines and lines[-1].startswith("hostpc calibrate: error: "), stderr
    return lines[-1]


def test_unreachable_robot_exit_3_one_line(tmp_path: Path,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "run"
    rig = truth_rig_file(sim_scenario(), tmp_path / "rig.json")
    code, stdout, stderr = run_cli(capsys, "calibrate", "--robot",
                                   f"127.0.0.1:{_closed_port()}", "--rig", str(rig),
                                   "--out", str(out))
    assert code == 3
    assert "cannot reach controller" in _error_line(stderr) and stdout == ""
    assert not (out / "run.json").exists()


def test_bad_rig_file_exit_2_before_connecting(tmp_path: Path,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "rig.json"
    bad.write_text(json.dumps({"format": "zerocal-stereo-rig", "version": 1}))
    out = tmp_path / "run"
    code, _, stderr = run_cli(capsys, "calibrate", "--robot", f"127.0.0.1:{_closed_port()}",
                              "--rig", str(bad), "--out", str(out))
    assert code == 2 and stderr.count("\n") == 1
    assert str(bad) in _error_line(stderr)
    assert not out.exists()
    code, _, stderr = run_cli(capsys, "calibrate", "--robot", "sim", "--rig",
                              str(tmp_path / "missing.json"), "--out", str(out))
    assert code == 2 and "cannot read rig file" in _error_line(stderr)


@pytest.mark.parametrize(
    "args, message",
    [
        (["--poses", "0"], "argument --poses: expected an integer >= 1, got '0'"),
        (["--max-correction", "inf"],
         "argument --max-correction: expected a finite number > 0, got 'inf'"),
        (["--verify-factor", "nan"],
         "argument --verify-factor: expected a finite number > 0, got 'nan'"),
        (["--verify-factor", "-1"],
         "argument --verify-factor: expected a finite number > 0, got '-1'"),
        (["--pixel-floor", "nan"],
         "argument --pixel-floor: expected a finite number >= 0, got 'nan'"),
        (["--rig-coverage", "0.4"],  # below the rig calibration's own coverage check
         "argument --rig-coverage: expected a finite number >= 0.5 and <= 1, got '0.4'"),
        (["--verify-alpha", "1"],
         "argument --verify-alpha: expected a finite number > 0 and < 1, got '1'"),
        (["--verify-tolerance", "0"],
         "argument --verify-tolerance: expected a finite number > 0, got '0'"),
        (["--robot", "127.0.0.1:"], "no port after ':'"),
        (["--effects", "+nonsense"], "unknown effect 'nonsense'"),
        (["--method", "sphere_probe", "--known", "target"],
         "target is not a sphere_probe frame"),
        (["--known", "flange"], "unknown frame 'flange'"),
        (["--robot", "host:99999"], "out of range"),
        (["--scenario", "x.yaml"], "--scenario needs --robot sim"),
        # the simulator speaks the zerocal protocol: never silently another driver's run
        (["--robot", "sim", "--driver", "ur"],
         "--robot sim --driver ur: the simulator speaks only the zerocal protocol; drop "
         "--driver for the simulator, or run controller-stub serve --ur --port 0, then "
         "hostpc calibrate --robot 127.0.0.1:PORT --driver ur"),
    ],
)
def test_bad_options_exit_2(args: list[str], message: str, tmp_path: Path,
                            capsys: pytest.CaptureFixture[str]) -> None:
    base = ["calibrate", "--robot", "127.0.0.1:1", "--out", str(tmp_path / "run")]
    try:
        code, _, stderr = run_cli(capsys, *base, *args)
    except SystemExit as exc:  # the argument parser's own check: one line, exit 2
        code, stderr = int(exc.code or 0), capsys.readouterr().err
    assert code == 2 and message in _error_line(stderr) and stderr.count("\n") == 1
    assert not (tmp_path / "run").exists()


def test_out_naming_a_file_exit_2_before_connecting(tmp_path: Path,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    afile = tmp_path / "afile"
    afile.write_text("x")
    for out in (afile, afile / "run"):
        code, _, stderr = run_cli(capsys, "calibrate", "--robot", "sim", "--out", str(out))
        assert code == 2 and stderr.count("\n") == 1
        assert f"{afile} is a file, not a folder" in _error_line(stderr)
    assert afile.read_text() == "x"


@pytest.mark.parametrize("line, message", [
    ('{"event":"sample"}', "phase None is not 'fit' or 'verify'"),
    ('{"event":"sample","phase":"fit","index":"x","status":"ok","sample":{}}',
     "index 'x' is not a non-negative integer"),
    ('{"event":"push","previous_offsets":"a","new_offsets":[0]}',
     "push event: previous_offsets is not a list of numbers"),
])
def test_damaged_journal_line_exit_2_one_line(line: str, message: str, tmp_path: Path,
                                              capsys: pytest.CaptureFixture[str]) -> None:
    run = tmp_path / "run"
    run.mkdir()
    (run / "run.json").write_text(json.dumps({"format": "zerocal-run/1", "robot": {
        "address": f"127.0.0.1:{_closed_port()}", "sim": False}}))
    (run / "journal.jsonl").write_text(line + "\n" + '{"event":"note"}\n')
    code, _, stderr = run_cli(capsys, "calibrate", "--resume", str(run))
    # unreachable controller (3) or the damaged line (2): the journal is read first
    assert code == 2, stderr
    assert "line 1" in _error_line(stderr) and message in _error_line(stderr)
    assert stderr.count("\n") == 1


def test_resume_of_a_folder_without_a_run_exit_2(tmp_path: Path,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    code, _, stderr = run_cli(capsys, "calibrate", "--resume", str(tmp_path))
    assert code == 2 and "not a calibration run folder" in _error_line(stderr)


def test_plan_that_cannot_separate_the_parameters_stops_before_moving(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    rig = truth_rig_file(sim_scenario(), tmp_path / "rig.json")
    with SimulatedController(sim_scenario(), tmp_path / "stub") as sim:
        q_start = sim.truth()["q_reported"]
        code, _, stderr = run_cli(
            capsys, "calibrate", "--robot", f"{sim.address.host}:{sim.address.port}",
            "--token", TOKEN, "--rig", str(rig), "--poses", "3", "--no-report",
            "--out", str(tmp_path / "run"))
        assert code == 2
        line = _error_line(stderr)
        assert "cannot separate" in line and "not separable" in line and "--poses" in line
        assert sim.truth()["q_reported"] == q_start  # the robot never moved
        assert "removed" in line
    assert not (tmp_path / "run").exists()  # so `--out run --poses 20` may start it again
