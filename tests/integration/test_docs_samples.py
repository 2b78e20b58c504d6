"""The docs' sample outputs are the tool's: `python docs/generate_samples.py --check` finds
no block that differs from what the commands print now (issue 29: diagnostics.md's sample
had drifted from the tool). About 20 s: one simulated calibration, a few diagnoses."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
GENERATOR = ROOT / "docs" / "generate_samples.py"


def test_the_docs_sample_outputs_match_the_tool() -> None:
    run = subprocess.run([sys.executable, str(GENERATOR), "--check"], capture_output=True,
                         text=True, timeout=300, cwd=ROOT)
    assert run.returncode == 0, run.stdout + run.stderr


def test_the_docs_have_sample_blocks_where_they_show_output() -> None:
    """Every fenced block that shows a `$ hostpc ...` prompt is a generated sample."""
    for path in sorted((ROOT / "docs").glob("*.md")):
        lines = path.read_text(encoding="utf-8").split("\n")
        for k, line in enumerate(lines):
            if line.startswith("$ hostpc"):
                opening = max(i for i in range(k) if lines[i].startswith("```"))
                assert lines[opening - 1].startswith("<!-- sample: "), f"{path.name}:{k + 1}"


def test_a_drifted_block_is_named(tmp_path: Path) -> None:
    page = tmp_path / "page.md"
    page.write_text("<!-- sample: hostpc robots -->\n```\n$ hostpc robots\nold\n```\n"
                    "<!-- /sample -->\n")
    run = subprocess.run([sys.executable, str(GENERATOR), "--check", str(page)],
                         capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert run.returncode == 1 and "drifted: " in run.stdout and "hostpc robots" in run.stdout
    assert "old" in page.read_text()  # --check writes nothing
    run = subprocess.run([sys.executable, str(GENERATOR), str(page)], capture_output=True,
                         text=True, timeout=120, cwd=ROOT)
    assert run.returncode == 0 and "ur5e             6 joints, DH" in page.read_text()


def test_the_camera_free_rig_recipe_is_the_one_generated() -> None:
    """docs/vision.md's recipe records the run the generator records, so the checked sample
    below it is the output of the recipe itself; README names the simulator's board."""
    recipe = re.search(r'RECORDED_RUN = "(.*)"', GENERATOR.read_text())
    assert recipe is not None
    vision = (ROOT / "docs" / "vision.md").read_text(encoding="utf-8")
    assert f"\n{recipe.group(1)}\n" in vision
    assert "--images runs/recorded/recording --board 9x6 --square 0.025" in vision
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    assert "--board 9x6 --square 0.025" in readme


def test_readme_commands_have_their_required_options() -> None:
    """README's import row lacked the required -o (argparse would stop at once)."""
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    for command in re.findall(r"`(hostpc import [^`]*)`", readme):
        assert " -o " in f"{command} ", command
    for command in re.findall(r"`(hostpc stereo-calibrate [^`]*)`", readme):
        assert all(f"{option} " in command for option in ("--images", "--board", "--square",
                                                          "--out")), command
