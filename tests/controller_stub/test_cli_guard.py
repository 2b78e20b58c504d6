"""`controller-stub serve` refuses to expose the default token on a network address."""

from __future__ import annotations

import pytest

from controller_stub.cli import _exposure_refusal, main
from controller_stub.scenario import scenario_from_dict


@pytest.mark.parametrize("host", ["127.0.0.1", "127.0.0.2", "::1", "localhost"])
def test_loopback_is_fine_with_the_default_token(host: str) -> None:
    assert _exposure_refusal(host, "zerocal-sim", scenario_from_dict({})) is None


@pytest.mark.parametrize("host", ["0.0.0.0", "192.168.1.10", "::", "robot-cell.local"])
def test_network_addresses_need_a_token_of_their_own(host: str) -> None:
    scenario = scenario_from_dict({})
    assert "give --token" in str(_exposure_refusal(host, "zerocal-sim", scenario))
    assert _exposure_refusal(host, "a-real-secret", scenario) is None
    custom = scenario_from_dict({"server": {"token": "cell-secret"}})
    assert _exposure_refusal(host, custom.server.token, custom) is None


def test_serve_exits_2_with_one_line_before_binding(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["serve", "--host", "0.0.0.0", "--port", "0"]) == 2
    captured = capsys.readouterr()
    assert captured.out == "" and captured.err.count("\n") == 1
    assert captured.err.startswith("controller-stub serve: error: --host 0.0.0.0")
