"""The simulated controller's refusal: the one exception of the Simulation contract."""

from __future__ import annotations


class SimulationRefused(Exception):  # noqa: N818 (name fixed by the contract)
    """The simulated controller refuses a request (limit, estop, injected fault).

    `code` is a short machine-readable reason (e.g. "offset_limit", "joint_limit", "estop",
    "refused_fault"); the message says it in words.
    """

    def __init__(self, code: str, message: str) -> None:
        super().__init__(message)
        self.code = code
