"""`hostpc fit --effects auto --loss L`: every model of the table, and the chosen fit, use
the loss asked for (it was dropped: the chosen fit said "linear")."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from hostpc.cli.main import main

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "ur5e_stereo.json"


@pytest.mark.parametrize("loss", ["linear", "cauchy"])
def test_auto_keeps_the_loss(loss: str, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["fit", str(EXAMPLE), "--effects", "auto", "--loss", loss, "--json"]) == 0
    document = json.loads(capsys.readouterr().out)
    assert document["loss"] == loss
    assert document["model_choice"]["chosen"]


def test_auto_with_other_effects_is_one_line(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["fit", str(EXAMPLE), "--effects", "auto,+geometry"]) == 2
    assert "'auto' chooses the whole model" in capsys.readouterr().err
