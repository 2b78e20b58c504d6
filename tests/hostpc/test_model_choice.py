"""`hostpc fit --effects auto`: the model chosen by pose-grouped held-out error, with the
one-standard-error rule toward the simpler model (hostpc.diagnostics.model_choice)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from hostpc.cli.main import main
from hostpc.dataset import save_dataset
from hostpc.diagnostics.model_choice import choose_model
from tests.hostpc.diagnose_support import hidden_world_point


def test_zero_offsets_in_the_data_choose_the_offsets_model() -> None:
    dataset = hidden_world_point({}, seed=12, n_samples=60, markers_per_pose=2).dataset
    choice = choose_model(dataset, ladder=False)
    names = [s.name for s in choice.scores]
    assert names[:3] == ["nominal", "offsets", "offsets + geometry"]
    assert choice.chosen == "offsets"  # +-0.5 deg offsets: nominal predicts far worse;
    # geometry adds parameters that do not predict better beyond one standard error
    scores = {s.name: s for s in choice.scores}
    assert scores["nominal"].score is not None and scores["offsets"].score is not None
    assert scores["nominal"].score > 10 * scores["offsets"].score
    assert "joint_offsets" in choice.fit.problem.effect_names


def test_the_chosen_model_is_within_one_standard_error_of_the_best(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    dataset = hidden_world_point({"geometry.a2": 4e-4, "geometry.d4": -3e-4}, seed=13,
                                 n_samples=90, markers_per_pose=3).dataset
    save_dataset(dataset, tmp_path / "d.json")
    assert main(["fit", str(tmp_path / "d.json"), "--effects", "auto", "--json"]) == 0
    document = json.loads(capsys.readouterr().out)
    choice = document["model_choice"]
    models = {m["name"]: m for m in choice["models"]}
    scored = [m for m in models.values() if m["held_out_score"] is not None]
    best = min(scored, key=lambda m: m["held_out_score"])
    chosen = models[choice["chosen"]]
    assert chosen["held_out_score"] <= best["held_out_score"] + best["standard_error"]
    assert all(m["free_parameters"] >= chosen["free_parameters"] for m in scored
               if m["held_out_score"] <= best["held_out_score"] + best["standard_error"])
    assert document["effects"] == chosen["effects"]
    assert main(["fit", str(tmp_path / "d.json"), "--effects", "auto"]) == 0
    out = capsys.readouterr().out
    assert "model chosen by pose-grouped held-out error" in out and "<- chosen" in out
