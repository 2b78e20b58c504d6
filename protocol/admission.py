"""Who gets a session, how fast a peer address may guess tokens, how often a peer may log.

The policies every zerocal server applies against hostile peers (the controller stub, the
camera service; the station's Modbus and HTTP ports use `protocol.connection_table` with
`LogBudget`), kept apart from the sockets (no asyncio, no sockets: the servers call them):

- `AuthThrottle`: failed authentications are counted per peer address (host, not port).
  After n failures every new session from that address waits `delay(n)` before it is served
  (0.1 s, 0.2 s, 0.4 s ... capped at `max_delay_s`), and the waits of concurrent sessions
  from one address are serialised: one auth attempt (a wrong proof closes the session) per
  delay per address. A session whose wait would exceed `max_wait_s` is refused at once
  instead (so reservations never pile up). Failures decay by time only: `forget_after_s`
  without a failure forgets them. A success does NOT forget them: one address may hold an
  operator and a guesser (NAT, a shared jump host, loopback), and an operator's login must
  not hand the guesser a fresh budget (it did: 200 guesses in 53 s instead of ~20 in 31 s).
- `LogBudget`: at most `burst` log lines per key (a reason, a message template) per
  `interval_s`, and the count of those held back, so a peer hammering a server cannot flood
  its log.
- `SessionSlots`: sessions in accept order, the unauthenticated ones apart. A new
  connection always gets a slot: if the unauthenticated ones are at their cap, or all slots
  are taken, an unauthenticated session is evicted: one from the peer address that holds
  the most unauthenticated sessions, preferring those that loiter (made requests other
  than hello and auth before authenticating: an operator authenticates at once), the
  oldest first. Only when every slot is held by an authenticated session is the newcomer
  refused. An operator with the token therefore gets in however many anonymous peers hold
  connections open (they also have to authenticate within the handshake deadline or be
  closed).

Times are seconds of a monotonic clock, passed in (no clock here: the server passes the
event loop's time).
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Hashable, Iterator
from dataclasses import dataclass, field
from typing import Generic, TypeVar

T = TypeVar("T", bound=Hashable)

MAX_TRACKED_ADDRESSES = 4096
"""Failure records kept at most (the oldest are forgotten first)."""


@dataclass
class _Failures:
    count: int = 0
    last_failure: float = 0.0
    next_slot: float = 0.0  # earliest time the next session from this address is served


@dataclass
class AuthThrottle:
    """Growing delay per peer address after failed authentications (see module docstring)."""

    base_delay_s: float = 0.1
    max_delay_s: float = 2.0
    max_wait_s: float = 5.0
    forget_after_s: float = 60.0
    _records: dict[str, _Failures] = field(default_factory=dict)

    def delay(self, failures: int) -> float:
        """Seconds between two auth attempts from an address with `failures` failures."""
        if failures <= 0:
            return 0.0
        return min(self.base_delay_s * 2.0 ** min(failures - 1, 30), self.max_delay_s)

    def failures(self, address: str, now: float) -> int:
        """Recent failed authentications from `address`."""
        record = self._record(address, now)
        return record.count if record is not None else 0

    def reserve(self, address: str, now: float) -> float | None:
        """Seconds a new session from `address` must wait before it is served, reserving
        its turn; None if it would have to wait longer than max_wait_s (refuse it)."""
        record = self._record(address, now)
        if record is None or record.count == 0:
            return 0.0
        start = max(now, record.next_slot)
        if start - now > self.max_wait_s:
            return None
        record.next_slot = start + self.delay(record.count)
        return start - now

    def failed(self, address: str, now: float) -> None:
        """Note a failed authentication from `address`."""
        record = self._record(address, now)
        if record is None:
            if len(self._records) >= MAX_TRACKED_ADDRESSES:
                del self._records[next(iter(self._records))]
            record = self._records[address] = _Failures()
        record.count += 1
        record.last_failure = now
        record.next_slot = max(record.next_slot, now + self.delay(record.count))

    def _record(self, address: str, now: float) -> _Failures | None:
        record = self._records.get(address)
        if record is not None and now - record.last_failure > self.forget_after_s:
            del self._records[address]
            return None
        return record


@dataclass
class LogBudget:
    """At most `burst` lines per key every `interval_s` (see module docstring)."""

    interval_s: float = 10.0
    burst: int = 1
    max_keys: int = 1024
    _windows: dict[Hashable, tuple[float, int, int]] = field(default_factory=dict)
    # key -> (window start, lines logged in it, events held back since the last line)

    def admit(self, key: Hashable, now: float) -> int | None:
        """None: do not log this event (it is counted). Else log it, noting the returned
        number of events of this key held back since the previous line."""
        start, logged, held = self._windows.get(key, (now - self.interval_s, 0, 0))
        if now - start >= self.interval_s:
            start, logged = now, 0
        if logged >= self.burst:
            self._windows[key] = (start, logged, held + 1)
            return None
        if key not in self._windows and len(self._windows) >= self.max_keys:
            del self._windows[next(iter(self._windows))]
        self._windows[key] = (start, logged + 1, 0)
        return held


@dataclass
class SessionSlots(Generic[T]):
    """Sessions in accept order; the policy of who is evicted (see module docstring).

    max_sessions: all sessions; max_unauthenticated: sessions not yet authenticated.
    """

    max_sessions: int
    max_unauthenticated: int
    _all: dict[T, None] = field(default_factory=dict)
    _unauthenticated: dict[T, str] = field(default_factory=dict)  # session -> peer address
    _loitering: set[T] = field(default_factory=set)

    def __len__(self) -> int:
        return len(self._all)

    def __iter__(self) -> Iterator[T]:
        return iter(list(self._all))

    @property
    def unauthenticated(self) -> int:
        """Sessions not yet authenticated."""
        return len(self._unauthenticated)

    def admit(self, session: T, address: str = "") -> tuple[bool, list[T]]:
        """Make room for `session` from peer `address`: (admitted, the sessions to evict for
        it). Evicted sessions are no longer counted; the caller closes them."""
        evicted: list[T] = []
        while self._unauthenticated and (
            len(self._unauthenticated) >= self.max_unauthenticated
            or len(self._all) >= self.max_sessions
        ):
            victim = self._victim()
            self.remove(victim)
            evicted.append(victim)
        if len(self._all) >= self.max_sessions:
            return False, evicted
        self._all[session] = None
        self._unauthenticated[session] = address
        return True, evicted

    def _victim(self) -> T:
        """The unauthenticated session to evict: from the address holding the most, a
        loiterer before the others, the oldest first."""
        per_address = Counter(self._unauthenticated.values())
        ranked = (
            (-per_address[address], session not in self._loitering, age, session)
            for age, (session, address) in enumerate(self._unauthenticated.items())
        )
        return min(ranked, key=lambda rank: rank[:3])[3]

    def loitering(self, session: T) -> None:
        """`session` made a request other than hello/auth before authenticating."""
        if session in self._unauthenticated:
            self._loitering.add(session)

    def authenticated(self, session: T) -> None:
        """`session` proved the token: it is no longer evictable."""
        self._unauthenticated.pop(session, None)
        self._loitering.discard(session)

    def remove(self, session: T) -> None:
        """`session` ended (or was evicted)."""
        self._all.pop(session, None)
        self._unauthenticated.pop(session, None)
        self._loitering.discard(session)
