"""Who keeps a connection on a server whose peers never authenticate (Modbus TCP, HTTP).

The station's Modbus port and live page have no token to tell the PLC or a browser from a
peer that only holds sockets open, so what a connection has *done* decides:

- a connection is *silent* until it completes its first request (a whole Modbus frame, an
  HTTP request), then *serving*; every completed request is activity;
- at most `max_connections` in all and `max_per_address` per peer address (host, not
  port). A newcomer always gets in: when a cap is reached, one connection is evicted: the
  silent ones first, among them (and then among the serving ones) from the address holding
  the most, the one idle the longest first. An idle-connection flood therefore evicts only
  itself, and a PLC that polls stays in however many sockets a peer opens;
- a silent connection is overdue `first_request_timeout_s` after it connected, a serving
  one `idle_timeout_s` after its last request (a slowloris that dribbles a byte at a time
  never completes a request, so dribbling does not keep it).

Same shape as `protocol.admission.SessionSlots` (the servers with a token use that one):
no clock, no sockets; times are seconds of a monotonic clock passed in, the server closes
what `admit` and `overdue` return.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Hashable, Iterator
from dataclasses import dataclass, field
from typing import Generic, TypeVar

T = TypeVar("T", bound=Hashable)


@dataclass
class _Peer:
    address: str
    connected_at: float
    last_request: float | None = None  # None: silent (no request completed yet)

    def idle_since(self) -> float:
        return self.connected_at if self.last_request is None else self.last_request


@dataclass
class ConnectionTable(Generic[T]):
    """The connections of one listening port and who is evicted (see module docstring)."""

    max_connections: int = 64
    max_per_address: int = 32
    first_request_timeout_s: float = 10.0
    idle_timeout_s: float = 120.0
    _peers: dict[T, _Peer] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.max_connections < 1 or self.max_per_address < 1:
            raise ValueError("connection caps must be at least 1")

    def __len__(self) -> int:
        return len(self._peers)

    def __iter__(self) -> Iterator[T]:
        return iter(list(self._peers))

    def per_address(self, address: str) -> int:
        """Connections held from `address`."""
        return sum(1 for peer in self._peers.values() if peer.address == address)

    def admit(self, connection: T, address: str, now: float) -> list[T]:
        """Count `connection` from peer `address`; returns the connections to evict for it
        (no longer counted; the caller closes them). The newcomer is always admitted."""
        evicted: list[T] = []
        while self._peers and self.per_address(address) >= self.max_per_address:
            evicted.append(self._evict(address))
        while self._peers and len(self._peers) >= self.max_connections:
            evicted.append(self._evict(None))
        self._peers[connection] = _Peer(address, now)
        return evicted

    def request_done(self, connection: T, now: float) -> None:
        """`connection` completed a request: it is serving, and active now."""
        peer = self._peers.get(connection)
        if peer is not None:
            peer.last_request = now

    def silent(self, connection: T) -> bool:
        """True while `connection` has not completed a request."""
        peer = self._peers.get(connection)
        return peer is not None and peer.last_request is None

    def remove(self, connection: T) -> None:
        """`connection` ended (or was evicted)."""
        self._peers.pop(connection, None)

    def overdue(self, now: float) -> list[T]:
        """Connections past their deadline (silent too long, or idle too long); they are no
        longer counted, the caller closes them."""
        late = [
            connection
            for connection, peer in self._peers.items()
            if now - peer.idle_since()
            > (self.first_request_timeout_s if peer.last_request is None else self.idle_timeout_s)
        ]
        for connection in late:
            self.remove(connection)
        return late

    def _evict(self, address: str | None) -> T:
        """Remove and return the connection to evict: from `address` if given (its cap is
        reached), else from all; silent first, then the crowding address, the longest idle."""
        crowd = Counter(peer.address for peer in self._peers.values())
        candidates = (
            (peer.last_request is not None, -crowd[peer.address], peer.idle_since(), age, conn)
            for age, (conn, peer) in enumerate(self._peers.items())
            if address is None or peer.address == address
        )
        victim = min(candidates, key=lambda rank: rank[:4])[4]
        self.remove(victim)
        return victim
