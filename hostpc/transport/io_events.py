"""`IoEventSubscription`: the IO edge events a controller pushes, queued for one consumer.

Created by `ControllerClient.subscribe_io()`; the client fans each `io_edge` out to every
open subscription. A full queue drops the edge with a warning (the controller is never
slowed down by a slow consumer).
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import AsyncIterator, Callable

from hostpc.errors import RequestTimeout
from hostpc.transport.types import IoEdgeEvent
from hostpc.transport.waiting import wait_for_reply

# the client's logger: log records keep the name they had before the client was split
logger = logging.getLogger("hostpc.transport.client")


class IoEventSubscription:
    """IO edge events pushed by the controller, in order, from subscription on.

    Use as an async iterator or call `get(timeout)`; `close()` (or leaving an `async with`)
    unsubscribes. Events arrive only on an authenticated session.
    """

    def __init__(self, maxsize: int, on_close: Callable[[IoEventSubscription], None]) -> None:
        """on_close: called once by `close()` (the client forgets the subscription)."""
        self._on_close = on_close
        self.queue: asyncio.Queue[IoEdgeEvent] = asyncio.Queue(maxsize)

    def deliver(self, event: IoEdgeEvent) -> None:
        """Queue one pushed edge (called by the client's receive loop; never blocks)."""
        try:
            self.queue.put_nowait(event)
        except asyncio.QueueFull:
            logger.warning("IO event queue full; dropping edge on line %d", event.line)

    async def get(self, timeout: float | None = None) -> IoEdgeEvent:
        """The next event; RequestTimeout if none arrives within `timeout` seconds."""
        try:
            return await wait_for_reply(self.queue.get(), timeout)
        except TimeoutError:
            raise RequestTimeout(f"no IO edge event within {timeout} s") from None

    def close(self) -> None:
        """Stop receiving events."""
        self._on_close(self)

    def __aiter__(self) -> AsyncIterator[IoEdgeEvent]:
        return self

    async def __anext__(self) -> IoEdgeEvent:
        return await self.queue.get()

    async def __aenter__(self) -> IoEventSubscription:
        return self

    async def __aexit__(self, *exc_info: object) -> None:
        self.close()
