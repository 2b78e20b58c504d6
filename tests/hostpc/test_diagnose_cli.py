"""`hostpc diagnose`: the JSON contract outside users rely on, the text, errors, speed."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

import hostpc
from hostpc.cli.main import main

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "ur5e_stereo_hidden_compliance.json"
CONTRACT_VARIABLE = re.compile(
    r"^((left|right|head)\.)?(q\d+|tau\d+|approach\d+)$|^(t|temperature|depth|speed)$|^extra\..+$")


def run_json(capsys: pytest.CaptureFixture[str], *args: str) -> dict:  # type: ignore[type-arg]
    """The --json document; the exit code says the verdict (0 adequate, 1 not)."""
    code = main(["diagnose", str(EXAMPLE), "--json", *args])
    document = json.loads(capsys.readouterr().out)
    assert code == (0 if document["adequate"] else 1)
    return document


def test_json_contract_with_ladder(capsys: pytest.CaptureFixture[str]) -> None:
    document = run_json(capsys, "--ladder")
    for key in ("rms", "max", "chi2_dof", "adequate", "candidates", "interactions", "ladder",
                "cv_rms", "cv_max", "chi2", "dof", "chi2_band", "noise", "effects", "advice",
                "residuals", "fit", "units"):
        assert key in document, key
    assert document["units"] == {"length": "m", "angle": "rad"}
    assert document["adequate"] is False
    assert 1e-4 < document["rms"] < 1e-3  # metres
    candidates = document["candidates"]
    assert candidates[0]["effect"] == "joint_compliance"
    for c in candidates:
        assert {"effect", "delta_bic", "rms", "cv_rms"} <= set(c)
    assert [c["significant"] for c in candidates] == sorted(
        (c["significant"] for c in candidates), reverse=True)
    interactions = document["interactions"]
    assert interactions[0] == max(interactions, key=lambda i: i["score"])
    for i in interactions:
        assert {"parameter", "variable", "score"} <= set(i)
        assert CONTRACT_VARIABLE.match(i["variable"]), i["variable"]
        assert i["parameter"].split(".")[0] in document["effects"] + ["geometry"]
    for pattern in document["residuals"]["patterns"]:
        assert CONTRACT_VARIABLE.match(pattern["variable"])
    assert len(document["residuals"]["norm"]) == document["n_samples"] == 120
    ladder = document["ladder"]
    assert [s["added"] for s in ladder] == [None, "joint_compliance"]
    assert ladder[0]["adequate"] is False and ladder[-1]["adequate"] is True
    for step in ladder:
        assert {"rms", "cv_rms", "cv_max", "chi2_dof", "adequate", "effects"} <= set(step)
    assert document["rms"] == ladder[0]["rms"]


def test_json_without_ladder_has_no_ladder_and_plus_effect(capsys: pytest.CaptureFixture[str]
                                                           ) -> None:
    document = run_json(capsys, "--effects", "+joint_compliance", "--cv-folds", "3")
    assert "ladder" not in document
    assert document["effects"] == ["joint_offsets", "tool", "target", "joint_compliance"]
    assert document["adequate"] is True
    assert document["cv_folds"] == 3
    assert "joint_compliance" not in [c["effect"] for c in document["candidates"]]


def test_text_output_and_report(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    report = tmp_path / "out" / "report.html"
    assert main(["diagnose", str(EXAMPLE), "--ladder", "--report", str(report)]) == 1
    text = capsys.readouterr().out
    assert "verdict: NOT adequate" in text
    assert "* joint_compliance" in text
    assert "joint_offsets.q2 varies with tau2" in text
    assert "--effects +joint_compliance" in text
    assert "ladder:" in text and "report written to" in text
    assert report.is_file() and report.read_text().startswith("<!DOCTYPE html>")


def test_plugin_option(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    plugin = tmp_path / "my_effect.py"
    plugin.write_text(
        "import numpy as np\nfrom hostpc.model.effect import Effect\n\n"
        "class Tilt(Effect):\n    name = 'tilt'\n    hook = 'joint'\n    is_linear = True\n"
        "    def parameter_names(self, ctx):\n        return ['k']\n"
        "    def basis(self, ctx):\n        b = np.zeros((ctx.n_samples, ctx.n_joints, 1))\n"
        "        b[:, 1, 0] = np.cos(ctx.q_cmd[:, 1])\n        return b\n")
    document = run_json(capsys, "--plugin", str(plugin), "--cv-folds", "0")
    assert "tilt" in [c["effect"] for c in document["candidates"]]
    assert document["plugins"] == [str(plugin)]
    document = run_json(capsys, "--plugin", str(plugin), "--effects", "+tilt", "--cv-folds", "0")
    assert "tilt" in document["effects"]


@pytest.mark.parametrize(("args", "message"), [
    (["--effects", "+no_such_effect"], "unknown effect 'no_such_effect'"),
    (["--candidates", "nope"], "candidate effect 'nope' is unknown"),
    (["--candidates", "depth_scale,tool"], "'tool' is a frame, not a candidate effect"),
    (["--alpha", "2"], "alpha 2.0: must be between 0 and 1"),
    (["--cv-folds", "-1"], "--cv-folds: expected 0 or an integer from 2 to 1000, got '-1'"),
])
def test_bad_options_exit_2(capsys: pytest.CaptureFixture[str], args: list[str],
                            message: str) -> None:
    assert main(["diagnose", str(EXAMPLE), *args]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err


def test_missing_dataset_exit_2(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    assert main(["diagnose", str(tmp_path / "missing.json")]) == 2
    assert "missing.json" in capsys.readouterr().err


def test_python_api_matches_cli(capsys: pytest.CaptureFixture[str]) -> None:
    diagnosis = hostpc.diagnose(EXAMPLE, effects=["joint_offsets", "tool", "target"],
                                cv_folds=0)
    document = run_json(capsys, "--cv-folds", "0")
    assert diagnosis.source == str(EXAMPLE)
    assert diagnosis.rms == pytest.approx(document["rms"])
    assert [c.effect for c in diagnosis.candidates] == [c["effect"]
                                                        for c in document["candidates"]]


def test_ladder_with_every_candidate(capsys: pytest.CaptureFixture[str]) -> None:
    """`hostpc diagnose --ladder` on 120 samples tries every candidate and climbs the ladder
    (its speed is measured in bench/, not asserted here: a loaded machine must not decide
    a unit test)."""
    assert main(["diagnose", str(EXAMPLE), "--json", "--ladder"]) == 1  # not adequate
    document = json.loads(capsys.readouterr().out.split("\n}\n")[0] + "\n}")
    assert len(document["candidates"]) >= 6 and len(document["ladder"]) == 2


def test_exit_codes_a_ci_job_can_gate_on(capsys: pytest.CaptureFixture[str],
                                          tmp_path: Path) -> None:
    """0 adequate, 1 not adequate (the model named, whatever the ladder finds), 2 bad input:
    a broken file, an unwritable report; never a traceback."""
    fast = ["--cv-folds", "0"]
    assert main(["diagnose", str(EXAMPLE), "--effects", "+joint_compliance", *fast]) == 0
    assert "verdict: adequate" in capsys.readouterr().out
    assert main(["diagnose", str(EXAMPLE), *fast]) == 1
    assert "verdict: NOT adequate" in capsys.readouterr().out
    assert main(["diagnose", str(EXAMPLE), "--ladder", "--json", *fast]) == 1
    assert json.loads(capsys.readouterr().out)["ladder"][-1]["adequate"] is True
    broken = tmp_path / "broken.json"
    broken.write_text('{"format": "zerocal-dataset/1", "samples": [')
    assert main(["diagnose", str(broken)]) == 2
    assert "broken.json" in capsys.readouterr().err
    assert main(["diagnose", str(EXAMPLE), "--effects", "+joint_compliance", *fast,
                 "--report", str(tmp_path)]) == 2  # a folder, not a file
    err = capsys.readouterr().err
    assert "--report" in err and "Traceback" not in err


def test_the_advised_command_keeps_the_robot_and_runs_as_printed(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A dataset read with --robot (here a DH table file, the ur5e the data was taken
    with, while the file names a ur10e): the advice's command carries the --robot, and run
    as printed it fits the very model of the advised row (it used to drop the option, and
    the command then fitted the file's ur10e)."""
    import shlex

    from hostpc.dataset import save_dataset
    from tests.hostpc.diagnose_support import hidden_world_point

    hidden = {"encoder_scale.s2": 1e-3, "encoder_scale.s3": 1e-3}
    save_dataset(hidden_world_point(hidden, seed=3, n_samples=120).dataset,
                 tmp_path / "data.json")
    document = json.loads((tmp_path / "data.json").read_text())
    document["robot"] = {"name": "ur10e"}
    (tmp_path / "data.json").write_text(json.dumps(document))
    table = Path(__file__).resolve().parents[1] / "data" / "ur5e_dh.json"

    assert main(["diagnose", str(tmp_path / "data.json"), "--robot", str(table),
                 "--json"]) == 1
    diagnosis = json.loads(capsys.readouterr().out)
    row = next(c for c in diagnosis["candidates"] if c["effect"] == "encoder_scale")
    advice = next(s for s in diagnosis["advice"] if "add encoder_scale" in s)
    printed = re.search(r"\((hostpc diagnose [^)]*)\)", advice)
    assert printed is not None
    argv = shlex.split(printed.group(1))[1:]
    assert argv[argv.index("--robot") + 1] == str(table)
    assert main([*argv, "--json"]) == 0  # the advised model explains the data
    advised = json.loads(capsys.readouterr().out)
    assert advised["rms"] == pytest.approx(row["rms"], rel=1e-6)


def test_ladder_text_pins_the_chosen_effects_and_their_figures(
        capsys: pytest.CaptureFixture[str]) -> None:
    """The 120-pose hidden-compliance example's diagnosis as printed (to the printed
    precision): the verdict, the ranked candidates with their figures, the ladder's steps.
    Work that makes the diagnosis quicker (issue 28) must leave every line here as it is."""
    assert main(["diagnose", str(EXAMPLE), "--ladder"]) == 1
    text = capsys.readouterr().out
    for line in (
        "  chi2/dof 1.287 (band 0.782..1.251 for 347 dof, p = 0.00024)",
        "  in-sample RMS 0.2086 mm, max 0.7667 mm",
        "  held-out (5-fold) RMS 0.2123 mm, max 0.7674 mm, whitened 1.180 sigma (1 = the "
        "stated noise)",
        "  - adding joint_compliance is significant (p = 4.3e-12, delta BIC -44.5)",
        "  - the residuals say joint_offsets.q2 varies with tau2 (p = 1.1e-12)",
        "    tau4           chi2      32.4 / 18  p = 0.019",
        "  * joint_compliance            -44.5     -38.8    0.2059    0.2112   1.087     1.095    "
            "4.3e-12",
        "  * encoder_scale               -39.4     -22.0    0.2064    0.2125   1.103     1.116    "
            "8.9e-11",
        "  * transmission_harmonic       -36.2      58.7    0.2025    0.2138   1.149     1.099    "
            "4.5e-10",
        "  * geometry                    -12.1      29.5    0.2100    0.2179   1.134     1.157    "
            "1.3e-05",
        "    thermal_expansion             0.0       3.5    0.2082    0.2119   1.177     1.282    "
            "   0.26",
        "    backlash                      0.0      28.5    0.2086    0.2128   1.197     1.285    "
            "   0.75",
        "  * joint_offsets.q2 varies with tau2            score   12.0  p = 1.1e-12",
        "  0    (current model)             0.2086    0.2123    0.7674   1.180     1.287  "
        "NOT adequate",
        "  1    joint_compliance            0.2059    0.2112    0.7815   1.087     1.095  "
        "adequate",
        "  joint_compliance.c5 below 0.000734 rad/(N m) (156 um at the measured points) would "
        "not be seen with these poses",
    ):
        assert line in text.splitlines(), line
    assert ("(joint_compliance given transmission_harmonic: not significant (p = 0.06, "
            "threshold 0.0005); transmission_harmonic given joint_compliance: not significant "
            "(p = 0.4, threshold 0.0005))") in text
