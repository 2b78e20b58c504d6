"""Issue 29's small items that are behaviour, each on the code that prints it: a wrongly
shaped plugin basis is the contract's one line; the robots table has no -0.000 and shows its
mounts; a compliance shows digits; the HTML sets quoted commands as code; the plan line and
the resume's progress line agree with a plan that grew."""

from __future__ import annotations

import json
import textwrap
from pathlib import Path

import numpy as np
import pytest

from hostpc.calibrate.journal import Journal
from hostpc.calibrate.more_poses import more_poses_message
from hostpc.calibrate.summary import plan_line
from hostpc.cli.main import main
from hostpc.errors import EffectError
from hostpc.fitting import fit
from hostpc.methods.base import Plan, SampleRecord
from hostpc.report.calibration import render_calibration_html
from hostpc.report.markup import prose

ROOT = Path(__file__).resolve().parents[2]
URDF = ROOT / "tests" / "data" / "arm7_prismatic.urdf"

BAD_BASIS = textwrap.dedent('''
    import numpy as np
    from hostpc.model.effect import Effect

    class BadBasis(Effect):
        name = "bad_basis"
        hook = "HOOK"
        unit = "rad"
        is_linear = True

        def parameter_names(self, ctx):
            return ["k"]

        def basis(self, ctx):
            return np.zeros((ctx.n_samples, ROWS, 2))   # two columns for one parameter
''')


@pytest.mark.parametrize(("hook", "rows", "got", "expected"), [
    ("joint", "ctx.n_joints", "(60, 6, 2)", "(60, 6, 1)"),
    ("geometry", "5 * ctx.n_joints", "(60, 30, 2)", "(60, 30, 1)")])
def test_a_wrongly_shaped_basis_is_the_contracts_one_line(tmp_path: Path, hook: str, rows: str,
                                                         got: str, expected: str) -> None:
    """The old code let numpy's matmul fail: 'effect failed: ValueError: matmul: Input
    operand 1 has a mismatch in its core dimension 0, with gufunc signature ...'."""
    from hostpc.dataset import load_dataset

    plugin = tmp_path / "bad_basis.py"
    plugin.write_text(BAD_BASIS.replace("HOOK", hook).replace("ROWS", rows))
    with pytest.raises(EffectError) as info:
        fit(load_dataset(ROOT / "examples" / "ur5e_stereo.json"), "+bad_basis",
            plugins=[plugin])
    message = str(info.value)
    assert message == f"effect 'bad_basis': basis has shape {got}, expected {expected}"
    assert "matmul" not in message and "\n" not in message


def test_the_robots_table_has_no_negative_zero_and_shows_its_mounts(
        capsys: pytest.CaptureFixture[str]) -> None:
    argv = ["robots", "--robot", str(URDF), "--base-link", "base_link", "--tip-link", "tool0"]
    assert main(argv) == 0
    text = capsys.readouterr().out
    assert "-0.000" not in text and "-0.00 " not in text  # the old table: alpha -0.000
    assert "base mount (T_base_link0, before joint 1): xyz [100.00, 0.00, 350.00] mm" in text
    assert "flange mount (T_link_flange, after the last joint): xyz [-19.60, -3.97, 130.00]" \
        in text
    assert main([*argv, "--json"]) == 0
    description = json.loads(capsys.readouterr().out)
    assert description["base_mount"] == {"xyz_mm": [100.0, 0.0, 350.0],
                                          "rpy_deg": [0.0, 0.0, 0.0]}
    assert description["flange_mount"]["rpy_deg"][1] == -90.0
    assert all(str(row[key]) != "-0.0" for row in description["joints"]
               for key in ("a_mm", "alpha_deg", "d_mm", "theta_deg"))
    assert main(["robots", "--robot", "ur5e", "--json"]) == 0  # a plain table: no mounts
    assert "base_mount" not in json.loads(capsys.readouterr().out)


def test_a_compliance_shows_digits() -> None:
    """A compliance of 3e-6 rad per N m printed '+0.0002 +- 0.0000 deg/(N m)'."""
    from hostpc.cli.format import display

    value, unit = display(3e-6, "rad/(N m)")
    sigma, _ = display(4e-8, "rad/(N m)")
    assert (value, unit) == ("+0.1719", "deg/(kN m)")
    assert sigma.lstrip("+") == "0.0023"


def test_quoted_commands_are_code_in_the_html() -> None:
    assert prose("run `hostpc diagnose a<b.json` first") == \
        "run <code>hostpc diagnose a&lt;b.json</code> first"
    assert prose("one ` backtick") == "one ` backtick"  # unpaired: left as it is
    result = {"robot": {"name": "ur5e"}, "method": "stereo_target",
              "push": {"status": "refused", "reason": "the model does not explain the "
                       "measurements; run `hostpc diagnose RUN/dataset.json` and rerun"},
              "offsets": {"joints": []}}
    page = render_calibration_html(result)
    assert "`" not in page.split("<body>", 1)[-1]
    assert "<code>hostpc diagnose RUN/dataset.json</code>" in page


def test_the_plan_line_says_the_plan_grew() -> None:
    plan = {"n_poses": 11, "n_verify": 10, "criterion": "D", "n_candidates": 1500}
    grown = {"n_planned": 60, "more_poses": "the model does not explain the 11 poses"}
    assert plan_line(plan, grown) == (
        "plan: 11 poses (D-optimal from 1500 candidates), grown to 60 fit and 10 "
        "verification poses when the model did not explain the first 11")
    assert plan_line({**plan, "n_verify": 4}, {"n_planned": 11, "more_poses": None}) == \
        "plan: 11 poses (D-optimal from 1500 candidates), 4 verification poses"


def test_a_resume_replays_the_further_poses_instead_of_measuring_them(tmp_path: Path) -> None:
    plan = Plan(q=np.zeros((11, 6)), q_verify=np.zeros((4, 6)), q_more=np.ones((49, 6)))
    journal = Journal(tmp_path)
    reason = "the model does not explain the 11 poses"
    assert more_poses_message(reason, journal, plan) == f"{reason}: measuring 49 more poses"
    for index in range(11 + 49):
        journal.record(SampleRecord(phase="fit", index=index, ok=True, sample={"q": []}))
        if index == 11 + 19:
            assert more_poses_message(reason, Journal(tmp_path), plan) == (
                f"{reason}: 49 more poses, 20 replayed from the journal, measuring 29")
    message = more_poses_message(reason, Journal(tmp_path), plan)
    assert "measuring" not in message and "replaying them from the journal" in message
