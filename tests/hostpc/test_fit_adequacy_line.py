"""`hostpc fit` never says a plain "converged: yes" for a model that does not explain the
data: a solver that converged with chi2/dof far above its band names the band and the next
command (`hostpc diagnose DATASET --ladder`), in the text and in the JSON."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from hostpc.cli.main import main
from hostpc.dataset import save_dataset
from hostpc.synthesize import synthesize_stereo_target

OFFSETS = {f"joint_offsets.q{j}": 0.002 * (-1) ** j for j in range(1, 7)}


@pytest.mark.parametrize("hidden", [True, False])
def test_converged_outside_the_band_is_not_a_plain_yes(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], hidden: bool) -> None:
    truth = {**OFFSETS, "encoder_scale.s2": 2e-3} if hidden else OFFSETS
    dataset = synthesize_stereo_target(truth, n_samples=60, seed=1,
                                       known=("tool", "target")).dataset
    path = tmp_path / "d.json"
    save_dataset(dataset, path)
    assert main(["fit", str(path), "--effects", "joint_offsets", "--cv-folds", "0"]) == 0
    text = capsys.readouterr().out
    assert main(["fit", str(path), "--effects", "joint_offsets", "--cv-folds", "0",
                 "--json"]) == 0
    adequacy = json.loads(capsys.readouterr().out)["model_adequacy"]
    if hidden:
        assert "converged: yes" not in text
        assert "converged (solver)" in text and "the model does not explain the data" in text
        assert f"next: hostpc diagnose {path} --ladder" in text
        # how far above, never "far above" at the band's own display precision
        assert "far above" not in text and (" times);" in text or "(by " in text)
        assert adequacy["explains_data"] is False
        assert adequacy["chi2_dof"] > adequacy["chi2_dof_upper"]
    else:
        assert "converged: yes" in text and "does not explain" not in text
        assert adequacy["explains_data"] is True and adequacy["next"] is None
