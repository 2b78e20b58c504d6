"""`hostpc camera serve` guards its token as `controller-stub serve` does: the public default
token is refused on a network address (anyone there could take pictures through the camera),
and the token can come from a private file (`--token-file`), which a nested command had not
been offered (review of the ninth stop)."""

from __future__ import annotations

from pathlib import Path

import pytest

from hostpc.cli.main import build_parser, main
from protocol.auth import is_loopback


@pytest.fixture(autouse=True)
def _no_token_in_the_environment(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("ZEROCAL_TOKEN", raising=False)


def test_the_default_token_is_refused_on_a_network_address_before_any_camera_opens(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    missing = str(tmp_path / "no-such-camera")  # opening it would fail with another message
    assert main(["camera", "serve", "--left", missing, "--right", missing,
                 "--host", "0.0.0.0", "--port", "0"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    assert "--host 0.0.0.0 is reachable from the network" in err
    assert "--token-file FILE" in err


def test_camera_serve_takes_a_token_file(tmp_path: Path) -> None:
    parser = build_parser("camera")
    token = tmp_path / "token"
    token.write_text("cell-secret\n")
    token.chmod(0o600)
    args = parser.parse_args(["camera", "serve", "--left", "a", "--right", "b",
                              "--token-file", str(token)])
    assert args.token_file == str(token)


@pytest.mark.parametrize("host, loopback", [
    ("127.0.0.1", True), ("127.0.0.2", True), ("::1", True), ("[::1]", True),
    ("localhost", True), ("0.0.0.0", False), ("::", False), ("192.168.1.10", False),
    ("robot-cell.local", False),
])
def test_is_loopback(host: str, loopback: bool) -> None:
    assert is_loopback(host) is loopback
