"""Exceptions of hostpc, grouped by what the caller must do.

The CLI maps each group to one exit code and prints the message on one line; nothing else
in hostpc prints or exits. Lower layers translate their own failures into these with
``raise ... from exc`` so the message names the offending value.
"""

from __future__ import annotations


class ZerocalError(Exception):
    """Base class of every error hostpc raises on purpose."""

    exit_code = 1


class InputError(ZerocalError):
    """The user's input is wrong (file, option, effect name, plugin): fix it and rerun."""

    exit_code = 2


class DatasetError(InputError):
    """A dataset file breaks the format contract; the message names the field and sample."""


class EffectError(InputError):
    """An unknown effect, or a plugin that cannot be loaded or breaks the effect contract."""


class ConnectionFailed(ZerocalError):
    """The controller cannot be reached (refused, unreachable, timed out while connecting)."""

    exit_code = 3


class ControllerError(ZerocalError):
    """The controller answered but refused or failed a request (code and reason in message)."""

    exit_code = 4


class RequestTimeout(ControllerError):
    """A request got no answer within its timeout."""


class ProtocolViolation(ControllerError):
    """The peer sent something the protocol does not allow."""
