"""The measurement-model contract over every registered model (see measurement_contract)."""

from __future__ import annotations

from pathlib import Path

import pytest

from hostpc.model.measurements import MeasurementModel, measurement_models
from tests.hostpc.measurement_contract import check_model


@pytest.mark.parametrize("name", sorted(measurement_models()))
def test_every_registered_model_keeps_the_contract(name: str, tmp_path: Path) -> None:
    cls: type[MeasurementModel] = measurement_models()[name]
    check_model(cls, tmp_path)


def test_the_built_in_models_are_registered() -> None:
    assert {"stereo_target", "sphere_probe", "dual_loop"} <= set(measurement_models())
