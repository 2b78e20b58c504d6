"""Copied rows are named, not counted silently as new measurements (review R2: a dataset
with every row twice got sqrt(2) smaller sigmas and no word about it)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from hostpc.cli.main import main

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "ur5e_stereo.json"


def test_a_copied_row_is_named_and_a_clean_file_is_not(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["fit", str(EXAMPLE)]) == 0
    assert "repeat another sample exactly" not in capsys.readouterr().out
    document = json.loads(EXAMPLE.read_text())
    document["samples"] = [*document["samples"], document["samples"][3],
                           document["samples"][7]]
    copied = tmp_path / "copied.json"
    copied.write_text(json.dumps(document))
    n = len(document["samples"])
    assert main(["fit", str(copied)]) == 0
    out = capsys.readouterr().out
    assert f"warning: 2 samples repeat another sample exactly (#{n - 2} = #3, #{n - 1} = #7)" \
        in out


def test_diagnose_names_copied_rows(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    document = json.loads(EXAMPLE.read_text())
    document["samples"] = [*document["samples"], document["samples"][5]]
    copied = tmp_path / "copied.json"
    copied.write_text(json.dumps(document))
    main(["diagnose", str(copied)])
    assert "warning: 1 sample repeats another sample exactly" in capsys.readouterr().out
