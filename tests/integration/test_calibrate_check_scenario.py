"""`hostpc calibrate --robot sim --scenario FILE --check` refuses what the run refuses.

A missing scenario file, broken YAML and a value the simulator rejects
(`motion.max_joint_acceleration: 0`) each end a real run with one line and exit 2; the
check said "options and files checked" and exit 0 for all three. Now the check reads the
file as the run does and has the simulator itself check the scenario (`controller-stub
serve --check`: nothing listens), and it creates no run folder."""

from __future__ import annotations

from pathlib import Path

import pytest

from hostpc.cli.main import main


def check(capsys: pytest.CaptureFixture[str], scenario: Path, out: Path
          ) -> tuple[int, str, str]:
    code = main(["calibrate", "--robot", "sim", "--scenario", str(scenario), "--check",
                 "--out", str(out)])
    stdout, stderr = capsys.readouterr()
    return code, stdout, stderr


@pytest.mark.parametrize(("text", "message"), [
    (None, "world.yaml: cannot read file"),
    ("motion: [\n", "world.yaml: cannot read"),
    ("motion:\n  max_joint_acceleration: 0\n",
     "refused the scenario: controller-stub serve: error: motion.max_joint_acceleration"),
])
def test_check_refuses_a_scenario_the_run_refuses(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], text: str | None,
        message: str) -> None:
    scenario = tmp_path / "world.yaml"
    if text is not None:
        scenario.write_text(text)
    code, stdout, stderr = check(capsys, scenario, tmp_path / "run")
    assert code == 2 and not stdout
    lines = stderr.strip().splitlines()
    assert len(lines) == 1 and message in lines[0], stderr
    assert not (tmp_path / "run").exists()


def test_check_passes_a_good_scenario_and_writes_nothing(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    scenario = tmp_path / "world.yaml"
    scenario.write_text("motion:\n  max_joint_acceleration: 2.0\n")
    code, stdout, stderr = check(capsys, scenario, tmp_path / "run")
    assert code == 0, stderr
    assert stdout.strip() == "hostpc calibrate: options and files checked"
    assert not (tmp_path / "run").exists()
