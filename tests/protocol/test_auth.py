"""HMAC challenge-response helpers."""

from __future__ import annotations

import hashlib
import hmac

from protocol import auth


def test_proof_is_hmac_sha256_over_both_nonces() -> None:
    server_nonce, client_nonce = "aa" * 16, "bb" * 16
    expected = hmac.new(
        b"tok", b"zerocal-auth-v1\x00client\x00" + b"aa" * 16 + b"\x00" + b"bb" * 16, hashlib.sha256
    ).hexdigest()
    assert auth.client_proof("tok", server_nonce, client_nonce) == expected


def test_proofs_depend_on_token_role_and_nonces() -> None:
    s, c = auth.new_nonce(), auth.new_nonce()
    assert s != c and len(s) == 32
    base = auth.client_proof("tok", s, c)
    assert base != auth.server_proof("tok", s, c)
    assert base != auth.client_proof("other", s, c)
    assert base != auth.client_proof("tok", auth.new_nonce(), c)
    assert base != auth.client_proof("tok", s, auth.new_nonce())
    assert auth.proofs_match(base, auth.client_proof("tok", s, c))
    assert not auth.proofs_match(base, "0" * 64)
