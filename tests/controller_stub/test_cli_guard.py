"""`controller-stub serve` refuses to expose the default token on a network address, refuses
an empty token, and takes its token from a private file or the environment."""

from __future__ import annotations

from pathlib import Path

import pytest

from controller_stub.cli import _exposure_refusal, main
from controller_stub.scenario.spec import scenario_from_dict


@pytest.mark.parametrize("host", ["127.0.0.1", "127.0.0.2", "::1", "localhost"])
def test_loopback_is_fine_with_the_default_token(host: str) -> None:
    assert _exposure_refusal(host, "zerocal-sim", scenario_from_dict({})) is None


@pytest.mark.parametrize("host", ["0.0.0.0", "192.168.1.10", "::", "robot-cell.local"])
def test_network_addresses_need_a_token_of_their_own(host: str) -> None:
    scenario = scenario_from_dict({})
    assert "give another with --token-file" in str(_exposure_refusal(host, "zerocal-sim", scenario))
    assert _exposure_refusal(host, "a-real-secret", scenario) is None
    custom = scenario_from_dict({"server": {"token": "cell-secret"}})
    assert _exposure_refusal(host, custom.server.token, custom) is None


@pytest.fixture(autouse=True)
def _no_token_in_the_environment(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("ZEROCAL_TOKEN", raising=False)


def test_serve_exits_2_with_one_line_before_binding(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["serve", "--host", "0.0.0.0", "--port", "0"]) == 2
    captured = capsys.readouterr()
    assert captured.out == "" and captured.err.count("\n") == 1
    assert captured.err.startswith("controller-stub serve: error: --host 0.0.0.0")


def serve_error(capsys: pytest.CaptureFixture[str], *args: str) -> str:
    assert main(["serve", "--port", "0", *args]) == 2
    captured = capsys.readouterr()
    assert captured.out == "" and captured.err.count("\n") == 1, captured.err
    return captured.err


def test_an_empty_token_is_refused_at_start(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    scenario = tmp_path / "empty-token.yaml"
    scenario.write_text("server:\n  token: ''\n")
    assert "token" in serve_error(capsys, "--scenario", str(scenario))
    assert "--token: the token is empty" in serve_error(capsys, "--token", "")
    monkeypatch.setenv("ZEROCAL_TOKEN", "  ")
    assert "$ZEROCAL_TOKEN: the token is empty" in serve_error(capsys)


def test_token_files_must_be_private_and_not_empty(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    token_file = tmp_path / "token"
    token_file.write_text("cell-secret\n")
    token_file.chmod(0o644)
    assert "readable by others (mode 0644)" in serve_error(capsys, "--token-file", str(token_file))
    token_file.write_text("\n")
    token_file.chmod(0o600)
    assert "the token is empty" in serve_error(capsys, "--token-file", str(token_file))
    assert "cannot read" in serve_error(capsys, "--token-file", str(tmp_path / "missing"))


def test_a_private_token_file_may_serve_the_network(tmp_path: Path) -> None:
    from controller_stub.cli import _resolve_token, build_parser

    token_file = tmp_path / "token"
    token_file.write_text("cell-secret\n")
    token_file.chmod(0o600)
    args = build_parser().parse_args(["serve", "--token-file", str(token_file)])
    scenario = scenario_from_dict({})
    assert _resolve_token(args, scenario) == "cell-secret"
    assert _exposure_refusal("0.0.0.0", "cell-secret", scenario) is None


def test_a_token_on_the_command_line_warns(capsys: pytest.CaptureFixture[str]) -> None:
    from controller_stub.cli import _resolve_token, build_parser

    args = build_parser().parse_args(["serve", "--token", "cell-secret"])
    assert _resolve_token(args, scenario_from_dict({})) == "cell-secret"
    assert "warning: --token is visible" in capsys.readouterr().err
