"""The docs are true: every effect in docs/effects.md is complete (<= 40 lines) and works
as a plugin file; the JSON schema in docs/diagnostics.md is the one --json prints."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from hostpc.diagnostics import diagnose
from hostpc.diagnostics.outliers import Outlier
from hostpc.fitting import fit
from hostpc.model.registry import load_plugin_file
from tests.hostpc.diagnose_support import hidden_dataset, inject

DOCS = Path(__file__).resolve().parents[2] / "docs"


def python_blocks(path: Path) -> list[str]:
    return re.findall(r"```python\n(.*?)```", path.read_text(encoding="utf-8"), re.S)


def effect_blocks() -> list[str]:
    return [b for b in python_blocks(DOCS / "effects.md") if "(Effect):" in b]


def write_plugin(tmp_path: Path, source: str) -> tuple[Path, str]:
    name = re.search(r'name = "(\w+)"', source)
    assert name is not None
    path = tmp_path / f"{name.group(1)}.py"
    path.write_text(source)
    return path, name.group(1)


def test_effects_doc_has_complete_short_examples() -> None:
    blocks = effect_blocks()
    assert len(blocks) >= 2
    for block in blocks:
        assert len(block.strip().splitlines()) <= 40


@pytest.mark.parametrize("index", [0, 1])
def test_doc_effect_loads_and_recovers_a_hidden_value(index: int, tmp_path: Path) -> None:
    path, name = write_plugin(tmp_path, effect_blocks()[index])
    effect = load_plugin_file(path)[name]()
    (parameter,) = [f"{name}.{p}" for p in effect.parameter_names(None)]  # type: ignore[arg-type]
    value = {"wrist_coupling": 1e-3, "depth_drift": 2e-3}[name]
    synthetic, _ = inject(hidden_dataset({}, seed=1), effect, {parameter: value})
    result = fit(synthetic.dataset, f"+{name}", plugins=[path], cv_folds=0)
    assert abs(result.value(parameter) - value) < 4 * result.sigma(parameter)
    assert result.sigma(parameter) < 0.3 * value


def test_doc_effect_is_found_as_a_plugin_candidate(tmp_path: Path) -> None:
    path, name = write_plugin(tmp_path, effect_blocks()[0])
    effect = load_plugin_file(path)[name]()
    synthetic, _ = inject(hidden_dataset({}, seed=1), effect, {f"{name}.k": 1e-3})
    found = diagnose(synthetic.dataset, plugins=[path], cv_folds=0, rank_cv_folds=0)
    assert found.candidates[0].effect == name and not found.adequate
    fixed = diagnose(synthetic.dataset, f"+{name}", plugins=[path], cv_folds=0)
    assert fixed.adequate


def test_json_schema_in_the_docs_matches_the_output() -> None:
    text = (DOCS / "diagnostics.md").read_text(encoding="utf-8")
    schema = text[text.index("## The JSON document"):]
    documented = set(re.findall(r"^\| `(\w+)` \|", schema, re.M))
    synthetic = hidden_dataset({}, seed=2, n_samples=40)
    document = diagnose(synthetic.dataset, ladder=True, cv_folds=0, rank_cv_folds=0).to_dict()
    assert documented == set(document)
    examples = dict(document, outliers=[Outlier(17, 8.1, 1e-12).to_dict()])
    for key in ("candidates", "interactions", "ladder", "outliers"):
        row = re.search(rf"^\| `{key}` \|(.*)$", schema, re.M)
        assert row is not None
        assert examples[key]
        for field in examples[key][0]:
            assert f'"{field}"' in row.group(1), (key, field)
    assert np.isfinite(document["chi2_dof"])
