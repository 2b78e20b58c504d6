"""A declared motor swap's push limit, the controller's own offset limit and the station's
swap keys (hostpc.calibrate.swaps); the staging itself runs against the simulator in
tests/integration/test_calibrate_swaps.py."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from hostpc.calibrate.swaps import (
    controller_limit_refusal,
    joint_limits_deg,
    parse_swapped,
    swap_message,
)
from hostpc.errors import ControllerError, InputError
from hostpc.methods.base import RunSettings
from hostpc.station.config import StationConfig
from hostpc.station.runner import calibrate_options


def test_swapped_joints_parse_and_size_their_own_limit_only() -> None:
    assert parse_swapped("J3") == (3,)
    assert parse_swapped("j6, 1") == (1, 6)
    assert parse_swapped(None) == ()
    for bad in ("J0", "X3", "J3,", "\u00b2", "J\u00b2", "\u0663"):  # isdigit, not int()
        with pytest.raises(InputError, match="--swapped"):
            parse_swapped(bad)
    settings = RunSettings(method="stereo_target", swapped=(3,), swap_limit_deg=30.0)
    np.testing.assert_array_equal(joint_limits_deg(6, settings), [2, 2, 30, 2, 2, 2])
    message = swap_message(settings)
    assert message is not None
    assert "J3" in message and "30 deg for that joint only" in message
    assert "2 deg for the others" in message
    assert swap_message(RunSettings(method="stereo_target")) is None
    with pytest.raises(InputError, match="J7"):
        joint_limits_deg(6, RunSettings(method="stereo_target", swapped=(7,)))
    # kept in run.json: a resume has the same limits
    again = RunSettings.from_dict(settings.to_dict())
    assert again.swapped == (3,) and again.swap_limit_deg == 30.0


class _Refused(ControllerError):
    def __init__(self, reason: str) -> None:
        super().__init__("offsets differ from the original by more than 5 deg")
        self.reason = reason


def test_the_controllers_own_limit_says_whose_it_is_and_what_to_do(tmp_path: Path) -> None:
    refusal = controller_limit_refusal(_Refused("offset_limit"), tmp_path / "run")
    assert refusal is not None and refusal.rule == "controller_limit"
    assert refusal.next_command(str(tmp_path / "run")) == (
        f"hostpc calibrate --resume {tmp_path / 'run'} --push")
    text = refusal.reason
    assert "controller's own offset limit" in text
    assert "not zerocal's --max-correction or --swap-limit" in text
    assert text.endswith(f"hostpc calibrate --resume {tmp_path / 'run'} --push")
    assert "--force" not in text  # --force would meet the same refusal again
    assert controller_limit_refusal(_Refused("estop"), tmp_path) is None


def test_station_passes_its_swap_keys_to_calibrate(tmp_path: Path) -> None:
    config = StationConfig(robot="sim", swapped="J3", swap_limit=30.0)
    options = calibrate_options(config, tmp_path / "run")
    assert options[options.index("--swapped") + 1] == "J3"
    assert options[options.index("--swap-limit") + 1] == "30"
    plain = calibrate_options(StationConfig(robot="sim"), tmp_path / "run")
    assert "--swapped" not in plain and "--swap-limit" not in plain


def test_a_superscript_joint_is_one_clear_line_exit_2(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """`--swapped \u00b2`: str.isdigit() is true, int() fails: an input error, no traceback."""
    from hostpc.cli.main import main

    code = main(["calibrate", "--robot", "sim", "--swapped", "\u00b2", "--no-report",
                 "--out", str(tmp_path / "run")])
    err = capsys.readouterr().err.strip()
    assert code == 2, err
    assert "Traceback" not in err and "--swapped \u00b2: expected joints like J3" in err
