"""Shared steps of the real-data tests (tests/data/README.md): import a CSV with `hostpc
import`, fit it at every built-in level, read the pose-grouped held-out table of
`hostpc fit --effects auto --json`. Public entry points only (the CLI, `hostpc.load_dataset`,
`hostpc.fit`), so the tests do not depend on where the fitting code lives."""

from __future__ import annotations

import contextlib
import io
import json
import math
from pathlib import Path
from typing import Any

import hostpc
from hostpc.cli.main import main

DATA = Path(__file__).resolve().parents[1] / "data"

FEW_DEGREES = math.radians(5.0)
"""The largest offset sigma at the measured noise (the stated sigma times sqrt(chi2/dof)) a
real fit may report: the fit holds at nominal any parameter whose sigma at the measured
noise the data leaves beyond 5 deg (docs/fitting.md), so none is reported above it."""


def import_csv(csv: Path, out: Path, *arguments: str) -> Path:
    """`hostpc import CSV ARGUMENTS -o OUT`; OUT."""
    assert main(["import", str(csv), *arguments, "-o", str(out)]) == 0
    return out


def fit_json(dataset: Path, effects: str) -> dict[str, Any]:
    """The JSON document of `hostpc fit DATASET --effects EFFECTS --json`."""
    buffer = io.StringIO()
    with contextlib.redirect_stdout(buffer):
        code = main(["fit", str(dataset), "--effects", effects, "--json"])
    assert code == 0, buffer.getvalue()[-2000:]
    document: dict[str, Any] = json.loads(buffer.getvalue())
    return document


def held_out_table(dataset: Path) -> dict[str, dict[str, Any]]:
    """The models `--effects auto` chose from, by name, each with its pose-grouped held-out
    score (whitened mean square per row), its standard error over poses and its held-out
    position RMS (m); the chosen one under the key "auto" as well."""
    choice = fit_json(dataset, "auto")["model_choice"]
    assert choice["folds"] == 5
    models = {model["name"]: model for model in choice["models"]}
    models["auto"] = models[choice["chosen"]]
    return models


def check_every_level(dataset: Path, nominal: list[str]) -> dict[str, Any]:
    """Fit the nominal model (frames only), the default (offsets + frames) and +geometry;
    each must converge and report no free offset with a sigma beyond a few degrees. Then
    `--effects auto`: every model of its table converged, and the chosen one is within one
    standard error of the best held-out score of a plausible model. Returns the fits by level."""
    data = hostpc.load_dataset(dataset)
    fits = {}
    for level, effects in (("nominal", nominal), ("offsets", None), ("geometry", "+geometry")):
        result = hostpc.fit(data, effects, cv_folds=5)
        assert result.converged, (level, result.message)
        for name, estimate in result.parameters.items():
            if name.startswith("joint_offsets.") and not estimate.fixed:
                assert estimate.std is not None, (level, name)
                assert estimate.std * math.sqrt(result.chi2_dof) < FEW_DEGREES, (level, name)
        fits[level] = result
    table = held_out_table(dataset)
    assert all(model["converged"] for model in table.values())
    # the best of the models auto may take (a geometry that moves a table length by over
    # 50 mm is never one, docs/real-data.md TALOS)
    best = min((model for model in table.values()
                if "implausible" not in (model["note"] or "")),
               key=lambda model: model["held_out_score"])
    assert table["auto"]["held_out_score"] <= best["held_out_score"] + best["standard_error"]
    fits["table"] = table
    return fits
