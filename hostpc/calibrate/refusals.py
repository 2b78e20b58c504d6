"""How a run stops when the controller says no: one line naming the refusal, and which
skipped poses are worth measuring again (a stopped move, e.g. an `abort`)."""

from __future__ import annotations

from hostpc.errors import ControllerError
from hostpc.methods.base import SampleRecord

MAX_POSE_ATTEMPTS = 3
"""A pose whose move was stopped (an `abort`) is measured up to this many times."""


def stopped(record: SampleRecord) -> bool:
    """True if a skipped pose's move was stopped (aborted), worth measuring again."""
    return str(record.reason or "").startswith("move stopped")


class RunStopped(ControllerError):
    """The controller refused or failed a request and the run stopped (resumable); code /
    reason: the controller's, if it gave them."""

    def __init__(self, message: str, code: str | None = None,
                 reason: str | None = None) -> None:
        super().__init__(message)
        self.code = code
        self.reason = reason


def refusal_text(exc: ControllerError) -> str:
    """One line naming a controller refusal: `controller refused (estop): ...`."""
    name = getattr(exc, "reason", None) or getattr(exc, "code", None)
    if name in ("auth_required", "auth_failed", "unauthenticated"):
        return f"controller refused (unauthenticated: check the token): {exc}"
    return f"controller refused ({name}): {exc}" if name else str(exc)
