"""The measurement-model contract over every registered model (see measurement_contract)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from hostpc.model.measurements import MeasurementModel, measurement_models
from tests.hostpc.measurement_contract import check_model


@pytest.mark.parametrize("name", sorted(measurement_models()))
def test_every_registered_model_keeps_the_contract(name: str, tmp_path: Path) -> None:
    cls: type[MeasurementModel] = measurement_models()[name]
    check_model(cls, tmp_path)


def test_the_built_in_models_are_registered() -> None:
    assert {"stereo_target", "sphere_probe", "dual_loop"} <= set(measurement_models())


def test_the_entry_point_scan_runs_once() -> None:
    from hostpc.plugins import entry_point_objects

    measurement_models()
    before = entry_point_objects.cache_info()
    for _ in range(3):
        measurement_models()
    after = entry_point_objects.cache_info()
    assert after.misses == before.misses and after.hits >= before.hits + 3


def test_a_plugin_may_not_take_a_built_in_name(tmp_path: Path) -> None:
    from hostpc.errors import EffectError

    path = tmp_path / "clash.py"
    path.write_text("from hostpc.model.measurements import MeasurementModel\n\n\n"
                    "class Mine(MeasurementModel):\n    name = 'stereo_target'\n")
    with pytest.raises(EffectError, match="clashes with a built-in"):
        measurement_models([path])


def test_a_method_without_a_model_is_one_clear_error() -> None:
    import dataclasses

    from hostpc.errors import InputError
    from hostpc.model.problem import build_problem

    example = measurement_models()["stereo_target"].example(np.random.default_rng(0))
    with pytest.raises(InputError, match="method 'laser' is not supported by the fit"):
        build_problem(dataclasses.replace(example, method="laser"))
