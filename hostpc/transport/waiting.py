"""A wait with a time limit that never loses a cancellation.

Python 3.11's `asyncio.wait_for` returns the result of an awaitable that completed in the
same loop step as its caller was cancelled, and the cancellation is lost (CPython gh-86296,
fixed in 3.12): a SIGTERM or Ctrl-C (hostpc.cli.termination) that came with a controller's
reply went unheard and the run went on to push (seen under load,
test_sigterm_stops_cleanly_and_a_sim_resume_keeps_time_increasing). Every wait of the
transport for a reply, an abort, an IO edge, a connection or a handshake goes through
`wait_for_reply`, and so does every wait outside it whose result a run goes on with (the UR
pre-check, the Modbus connection, the camera service's reads); a plain `asyncio.wait_for`
elsewhere waits on clean-up only and says why a lost cancel is harmless there.
"""

from __future__ import annotations

import asyncio
from collections.abc import Awaitable, Callable
from typing import TypeVar

T = TypeVar("T")


async def wait_for_reply(awaitable: Awaitable[T], timeout: float | None,
                         dropped: Callable[[T], object] | None = None) -> T:
    """`asyncio.wait_for(awaitable, timeout)` that re-raises a cancellation that came in the
    same loop step as the result. The result is dropped then, as if it had come a moment
    later; `dropped` releases it (e.g. closes a connection just opened)."""
    task = asyncio.current_task()
    cancels = task.cancelling() if task is not None else 0
    result = await asyncio.wait_for(awaitable, timeout)
    if task is not None and task.cancelling() > cancels:
        if dropped is not None:
            dropped(result)
        raise asyncio.CancelledError
    return result
