"""Rate-limited, traceback-free logging for the servers a hostile peer can reach.

A peer that sends a thousand bad requests a second must not write a thousand tracebacks a
second: pymodbus logs a 1.2 KB traceback (inside the message text) per request it cannot
serve, asyncio logs one per failed accept. `RateLimitedLogFilter` on those loggers lets at
most `burst` warnings and errors per (logger, message template) through every `interval_s`
(information lines pass untouched: a peer does not cause them), cut to
their first line, without exception text, and says on the next line let through how many
it held back (`protocol.admission.LogBudget`, the policy every server shares).
"""

from __future__ import annotations

import logging
import time

from protocol.admission import LogBudget

LOG_INTERVAL_S = 10.0
LOG_BURST = 5
MAX_LINE = 300
"""Characters of a record's message kept (the first line only)."""


class RateLimitedLogFilter(logging.Filter):
    """At most `burst` records per logger and message template every `interval_s`; each one
    line, no traceback (see module docstring)."""

    def __init__(self, interval_s: float = LOG_INTERVAL_S, burst: int = LOG_BURST) -> None:
        super().__init__()
        self.budget = LogBudget(interval_s=interval_s, burst=burst)

    def filter(self, record: logging.LogRecord) -> bool:
        if record.levelno < logging.WARNING:  # progress and timing lines: not a peer's doing
            return True
        held = self.budget.admit((record.name, str(record.msg)), time.monotonic())
        if held is None:
            return False
        try:
            text = record.getMessage()
        except Exception:  # a record with bad arguments still gets its one line
            text = str(record.msg)
        line = text.splitlines()[0] if text else ""
        if len(line) > MAX_LINE:
            line = line[:MAX_LINE] + " ..."
        if record.exc_info and record.exc_info[1] is not None:
            error = record.exc_info[1]
            said = str(error).splitlines()[0][:200] if str(error) else ""
            line += f" ({type(error).__name__}: {said})"
        if held:
            line += f" ({held} more like this since the last report)"
        record.msg, record.args = line, None
        record.exc_info, record.exc_text, record.stack_info = None, None, None
        return True


def limit_logging(*names: str) -> None:
    """Put one `RateLimitedLogFilter` on each named logger (once; idempotent)."""
    for name in names:
        target = logging.getLogger(name)
        if not any(isinstance(f, RateLimitedLogFilter) for f in target.filters):
            target.addFilter(RateLimitedLogFilter())


SERVER_LOGGERS = ("asyncio", "pymodbus.logging", "aiohttp.server", "aiohttp.web",
                  "aiohttp.access", "aiohttp.internal")
"""The third-party loggers a peer can make write (their own records)."""
