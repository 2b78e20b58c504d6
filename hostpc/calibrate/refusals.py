"""How a run stops when the controller says no: one line naming the refusal, and which
skipped poses are worth measuring again (a stopped move, e.g. an `abort`); and a refused
push as one structured value (`PushRefusal`), the journal's `push_refused` event."""

from __future__ import annotations

from dataclasses import dataclass

from hostpc.errors import ControllerError
from hostpc.json_object import JsonObject
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


RUN = "{run}"
"""Stands for the run folder in a refusal's next command (filled in when it is shown)."""


@dataclass(frozen=True)
class PushRefusal:
    """Why a push was refused, as the `push_refused` journal event keeps it.

    reason: the one line shown; rule: which guard refused (``not_converged``,
    ``model``: the model does not explain the data, ``correction_limit``: a joint beyond
    its push limit, ``reference_moved``, ``controller_limit``: the controller's own);
    joint: the joint a limit refused (1-based) and limit_deg that limit; declare: the joint
    to declare swapped (``--swapped J3``), None if declaring is not the fix; next: the
    next command's words after ``hostpc``, with ``RUN`` for the run folder."""

    reason: str
    rule: str
    next: tuple[str, ...]
    joint: int | None = None
    limit_deg: float | None = None
    declare: int | None = None

    def next_command(self, run_dir: str) -> str:
        """The next command, copy-pasteable, for the run folder `run_dir`."""
        return " ".join(["hostpc", *(str(run_dir) if w == RUN else w for w in self.next)])

    def to_event(self) -> JsonObject:
        """The `push_refused` event's fields (the journal adds its name)."""
        return {"reason": self.reason, "rule": self.rule, "joint": self.joint,
                "limit_deg": self.limit_deg, "declare": self.declare, "next": list(self.next)}

    @classmethod
    def from_event(cls, event: JsonObject) -> PushRefusal | None:
        """The refusal of a `push_refused` event; None for a journal written before the
        event had its ``rule`` and ``next`` (the outcome then reads its text)."""
        words = event.get("next")
        if not isinstance(event.get("rule"), str) or not isinstance(words, list) or not words:
            return None
        joint, declare, limit = event.get("joint"), event.get("declare"), event.get("limit_deg")
        return cls(str(event.get("reason") or ""), str(event["rule"]),
                   tuple(str(w) for w in words),
                   joint=int(joint) if isinstance(joint, int) else None,
                   limit_deg=float(limit) if isinstance(limit, int | float) else None,
                   declare=int(declare) if isinstance(declare, int) else None)


def resume_with(*options: str) -> tuple[str, ...]:
    """`calibrate --resume RUN OPTIONS...` as a refusal's next command."""
    return ("calibrate", "--resume", RUN, *options)
