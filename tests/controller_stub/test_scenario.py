"""Scenario loading and validation: every error names its field in one line."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from controller_stub.scenario.spec import (
    Scenario,
    ScenarioError,
    default_scenario,
    load_scenario,
    scenario_from_dict,
)

SCENARIO_DIR = Path(__file__).resolve().parents[2] / "controller_stub" / "scenarios"


def test_default_scenario_loads() -> None:
    sc = default_scenario()
    assert sc.robot == "ur5e"
    assert sc.camera.image_width == 1280 and sc.camera.image_height == 1024


@pytest.mark.parametrize("path", sorted(SCENARIO_DIR.glob("*.yaml")), ids=lambda p: p.name)
def test_example_scenarios_load(path: Path) -> None:
    assert isinstance(load_scenario(path), Scenario)


def test_json_scenario(tmp_path: Path) -> None:
    path = tmp_path / "s.json"
    path.write_text(json.dumps({"seed": 7, "robot": "ur10e"}))
    sc = load_scenario(path)
    assert sc.seed == 7 and sc.robot == "ur10e"


@pytest.mark.parametrize(
    ("data", "field"),
    [
        ({"robot": "puma"}, "robot"),
        ({"truth": {"backlash": [0.001] * 5}}, "truth.backlash"),
        ({"truth": {"backlash": [-0.001] * 6}}, "truth.backlash.0"),
        ({"truth": {"zero_errors": [0.0] * 7}}, "truth.zero_errors"),
        ({"truth": {"zero_errors": {"random_deg": -1}}}, "truth.zero_errors.random_deg"),
        ({"truth": {"transmission_harmonic": [[0, 0, 0]] * 6}}, "truth.transmission_harmonic.0"),
        ({"truth": {"thermal_drift": {"d": [0.0] * 3}}}, "truth.thermal_drift.d"),
        ({"camera": {"fx": -5}}, "camera.fx"),
        ({"camera": {"distortion": [0, 0]}}, "camera.distortion"),
        ({"camera": {"fxx": 5}}, "camera.fxx"),
        ({"target": {"radius": 0.2}}, "target"),
        ({"motion": {"q_min": [0.0] * 6, "q_max": [0.0] * 6}}, "motion.q_max"),
        ({"faults": {"refuse_move_indices": [-1]}}, "faults.refuse_move_indices.0"),
        ({"probe": {"io_line": 9}}, "probe.io_line"),
        ({"server": {"offset_limit_rad": 0}}, "server.offset_limit_rad"),
    ],
)
def test_errors_name_the_field(data: dict, field: str) -> None:
    with pytest.raises(ScenarioError) as info:
        scenario_from_dict(data)
    message = str(info.value)
    assert message.startswith(field + ":"), message
    assert "\n" not in message


def test_bad_yaml_and_missing_file(tmp_path: Path) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text("seed: [1, 2\n")
    with pytest.raises(ScenarioError, match="bad.yaml"):
        load_scenario(bad)
    with pytest.raises(ScenarioError, match="cannot read"):
        load_scenario(tmp_path / "missing.yaml")
    listed = tmp_path / "list.yaml"
    listed.write_text("- 1\n- 2\n")
    with pytest.raises(ScenarioError, match="expected a mapping"):
        load_scenario(listed)


def test_scenario_error_is_value_error() -> None:
    assert issubclass(ScenarioError, ValueError)
