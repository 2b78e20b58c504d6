"""`hostpc fit` as a user runs it: summary, JSON contract, and one-line errors (exit 2)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


def hostpc(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "hostpc.cli.main", *args],
                          capture_output=True, text=True, timeout=120)


def test_fit_summary_shows_degrees_mm_and_warnings() -> None:
    run = hostpc("fit", str(EXAMPLES / "ur5e_stereo.json"))
    assert run.returncode == 0, run.stderr
    assert "joint_offsets.q2" in run.stdout and "deg" in run.stdout and "mm" in run.stdout
    assert "chi2/dof" in run.stdout
    assert "not separable" in run.stdout


def test_fit_json_contract() -> None:
    run = hostpc("fit", str(EXAMPLES / "ur5e_stereo_known_frames.json"), "--json")
    assert run.returncode == 0, run.stderr
    doc = json.loads(run.stdout)
    for key in ("parameters", "rms", "max", "chi2_dof", "converged", "rank", "unidentifiable"):
        assert key in doc
    assert set(doc["parameters"]["joint_offsets.q3"]) >= {"value", "std"}
    truth = json.loads((EXAMPLES / "ur5e_stereo_known_frames.truth.json").read_text())["truth"]
    for name, value in truth.items():
        got = doc["parameters"][name]
        assert abs(got["value"] - value) < 3 * got["std"]


def write(tmp_path: Path, name: str, text: str) -> str:
    path = tmp_path / name
    path.write_text(text)
    return str(path)


@pytest.mark.parametrize("case, expected", [
    ("malformed", "not valid JSON"),
    ("format", "format"),
    ("joints", "samples[0].q"),
    ("nan", "samples[1].p"),
    ("cov", "samples[2].cov"),
    ("effect", "unknown effect 'bogus'"),
    ("plugin", "failed to import"),
    ("missing", "file not found"),
])
def test_bad_input_is_one_line_exit_2(tmp_path: Path, case: str, expected: str) -> None:
    doc = json.loads((EXAMPLES / "ur5e_stereo_known_frames.json").read_text())
    args: list[str] = []
    if case == "malformed":
        path = write(tmp_path, "d.json", '{"format": "zerocal-dataset/1",')
    elif case == "format":
        doc["format"] = "zerocal-dataset/9"
        path = write(tmp_path, "d.json", json.dumps(doc))
    elif case == "joints":
        doc["samples"][0]["q"] = doc["samples"][0]["q"][:5]
        path = write(tmp_path, "d.json", json.dumps(doc))
    elif case == "nan":
        path = write(tmp_path, "d.json", json.dumps(doc).replace(
            json.dumps(doc["samples"][1]["p"][0]), "NaN", 1))
    elif case == "cov":
        doc["samples"][2]["cov"] = [[1e-8, 0, 0], [0, -1e-8, 0], [0, 0, 1e-8]]
        path = write(tmp_path, "d.json", json.dumps(doc))
    else:
        path = str(EXAMPLES / "ur5e_stereo_known_frames.json")
        if case == "effect":
            args = ["--effects", "joint_offsets,bogus"]
        elif case == "plugin":
            args = ["--plugin", write(tmp_path, "p.py", "import no_such_module_xyz\n")]
        else:
            path = str(tmp_path / "absent.json")
    run = hostpc("fit", path, *args)
    assert run.returncode == 2, (run.stdout, run.stderr)
    lines = run.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in run.stderr, run.stderr
    assert expected in lines[0], lines[0]
    assert run.stdout == ""
