"""The shared admission policies of servers without a token (Modbus, HTTP) and the log
budget of every server: pure, with explicit times."""

from __future__ import annotations

import pytest

from protocol.admission import AuthThrottle, LogBudget
from protocol.connection_table import ConnectionTable


def test_a_flood_of_silent_connections_evicts_only_itself() -> None:
    table: ConnectionTable[str] = ConnectionTable(max_connections=4, max_per_address=4)
    assert table.admit("plc", "10.0.0.2", 0.0) == []
    table.request_done("plc", 0.1)
    evicted = []
    for k in range(1100):
        evicted += table.admit(f"idle{k}", "10.0.0.9", 1.0 + k * 1e-3)
    assert "plc" not in evicted and len(evicted) == 1100 - 3
    assert sorted(table) == ["idle1097", "idle1098", "idle1099", "plc"]
    assert table.admit("plc2", "10.0.0.2", 3.0) == ["idle1097"]  # the newcomer gets in


def test_the_per_address_cap_evicts_that_address_silent_first_then_longest_idle() -> None:
    table: ConnectionTable[str] = ConnectionTable(max_connections=10, max_per_address=3)
    table.admit("other", "10.0.0.5", 0.0)
    for name, t in (("a", 1.0), ("b", 2.0), ("c", 3.0)):
        table.admit(name, "127.0.0.1", t)
        table.request_done(name, t)
    table.request_done("a", 5.0)  # a polls: b is the longest idle
    assert table.admit("d", "127.0.0.1", 6.0) == ["b"]
    assert table.admit("e", "127.0.0.1", 7.0) == ["d"]  # silent before serving
    assert sorted(table) == ["a", "c", "e", "other"] and table.per_address("127.0.0.1") == 3


def test_silent_and_idle_connections_are_overdue_at_their_deadlines() -> None:
    table: ConnectionTable[str] = ConnectionTable(first_request_timeout_s=10.0,
                                                  idle_timeout_s=60.0)
    table.admit("silent", "h", 0.0)
    table.admit("dribbler", "h", 0.0)  # bytes arrive, but never a whole request
    table.admit("plc", "h", 0.0)
    table.request_done("plc", 5.0)
    assert table.silent("dribbler") and not table.silent("plc")
    assert table.overdue(9.0) == []
    assert table.overdue(10.5) == ["silent", "dribbler"]
    assert table.overdue(64.0) == []
    assert table.overdue(65.5) == ["plc"] and len(table) == 0
    with pytest.raises(ValueError):
        ConnectionTable(max_connections=0)


def test_the_log_budget_lets_one_line_per_interval_through_with_the_count_held_back() -> None:
    budget = LogBudget(interval_s=10.0, burst=2)
    lines = [budget.admit("wrong unit", t * 0.01) for t in range(1000)]  # 10 s of events
    assert lines[:2] == [0, 0] and all(line is None for line in lines[2:])
    assert budget.admit("wrong unit", 10.0) == 998  # the next window reports what it held
    assert budget.admit("other", 10.0) == 0  # keys are counted apart


def test_a_login_does_not_forget_the_failures_of_the_address() -> None:
    throttle = AuthThrottle(base_delay_s=0.1, max_delay_s=2.0, forget_after_s=60.0)
    for t in range(5):
        throttle.failed("127.0.0.1", float(t))
    assert not hasattr(throttle, "succeeded")  # failures decay by time only
    assert throttle.failures("127.0.0.1", 30.0) == 5
    assert throttle.reserve("127.0.0.1", 30.0) == 0.0  # its last delay is long past
    assert throttle.reserve("127.0.0.1", 30.0) == pytest.approx(1.6)
    assert throttle.failures("127.0.0.1", 64.5) == 0  # a quiet minute forgets them
