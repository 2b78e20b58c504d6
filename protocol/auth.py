"""HMAC-SHA256 challenge-response on a shared token; the token never crosses the wire.

The client sends a fresh nonce in `hello`, the server a fresh nonce in `hello_reply`. The
client proves it holds the token with

    client_proof = HMAC-SHA256(token, "zerocal-auth-v1" 0 "client" 0 server_nonce 0 client_nonce)

and the server answers with the same MAC under the label "server", so the client also knows
it reached a controller that holds the token (mutual authentication). Both nonces are fresh
per connection, so a recorded proof cannot be replayed. Proofs are compared with
`hmac.compare_digest`.
"""

from __future__ import annotations

import hashlib
import hmac
import secrets
import stat
from pathlib import Path

_CONTEXT = b"zerocal-auth-v1"
NONCE_BYTES = 16


def new_nonce() -> str:
    """A fresh random nonce (hex, 32 characters)."""
    return secrets.token_hex(NONCE_BYTES)


def _mac(token: str, label: bytes, server_nonce: str, client_nonce: str) -> str:
    message = b"\x00".join(
        (_CONTEXT, label, server_nonce.encode("ascii"), client_nonce.encode("ascii"))
    )
    return hmac.new(token.encode("utf-8"), message, hashlib.sha256).hexdigest()


def client_proof(token: str, server_nonce: str, client_nonce: str) -> str:
    """The proof the client sends in `auth` (hex)."""
    return _mac(token, b"client", server_nonce, client_nonce)


def server_proof(token: str, server_nonce: str, client_nonce: str) -> str:
    """The proof the server sends in `auth_reply` (hex)."""
    return _mac(token, b"server", server_nonce, client_nonce)


def proofs_match(expected: str, received: str) -> bool:
    """Constant-time comparison of two hex proofs."""
    return hmac.compare_digest(expected.encode("ascii"), received.encode("ascii"))


def read_token_file(path: Path) -> str:
    """The shared token in `path` (its first line, stripped), for every command that takes
    `--token-file`; ValueError (one line, naming the file) if it cannot be read, is not a
    regular file, is readable by group or others (mode 0600 or stricter), or is empty."""
    try:
        info = path.stat()
    except OSError as exc:
        raise ValueError(f"--token-file {path}: cannot read ({exc.strerror})") from None
    if not stat.S_ISREG(info.st_mode):
        raise ValueError(f"--token-file {path}: not a regular file")
    if info.st_mode & 0o077:
        raise ValueError(
            f"--token-file {path}: readable by others (mode {stat.S_IMODE(info.st_mode):04o}); "
            f"chmod 600 {path}"
        )
    try:
        with path.open(encoding="utf-8") as handle:
            first = handle.readline(4096)
    except (OSError, UnicodeDecodeError) as exc:
        raise ValueError(f"--token-file {path}: cannot read ({exc})") from None
    token = first.strip()
    if not token:
        raise ValueError(f"--token-file {path}: the token is empty")
    return token


def is_loopback(host: str) -> bool:
    """Whether a server bound to `host` is reachable from this machine only: "localhost" or
    a loopback address. A host name is not (it may resolve to anything)."""
    import ipaddress

    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False
