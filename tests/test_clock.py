"""tpad_rt.clock: the virtual clock runs events in time order at their own times, and only moves when told."""

from __future__ import annotations

import numpy as np
import pytest

from tpad_rt.clock import MonotonicClock, VirtualClock


def test_events_run_in_time_order_each_reading_its_own_time() -> None:
    clock = VirtualClock(start_ns=100)
    seen: list[tuple[str, int]] = []
    clock.at(300, lambda: seen.append(("c", clock.now_ns())))
    clock.at(200, lambda: seen.append(("a", clock.now_ns())))
    clock.at(200, lambda: seen.append(("b", clock.now_ns())))  # a tie runs in the order scheduled
    clock.sleep_until_ns(250)
    assert seen == [("a", 200), ("b", 200)] and clock.now_ns() == 250
    assert clock.next_event_ns() == 300
    clock.advance_by(50)
    assert seen[-1] == ("c", 300) and clock.next_event_ns() is None


def test_an_event_may_schedule_another_within_the_same_advance() -> None:
    clock = VirtualClock()
    ticks: list[int] = []

    def tick() -> None:
        ticks.append(clock.now_ns())
        if len(ticks) < 5:
            clock.at(clock.now_ns() + 10, tick)

    clock.at(0, tick)
    clock.advance_to(1000)
    assert ticks == [0, 10, 20, 30, 40]


def test_it_never_moves_backwards_and_a_past_event_runs_at_the_next_advance() -> None:
    clock = VirtualClock(start_ns=1000)
    clock.advance_to(10)
    assert clock.now_ns() == 1000
    ran: list[int] = []
    clock.at(5, lambda: ran.append(clock.now_ns()))
    assert ran == []
    clock.advance_by(0)
    assert ran == [1000]
    with pytest.raises(ValueError, match="negative"):
        clock.advance_by(-1)


@pytest.mark.parametrize("bad", [1.5, "7", True, None, float("nan")])
def test_a_time_must_be_a_whole_number_of_ns(bad: object) -> None:
    with pytest.raises(ValueError, match="whole number of ns"):
        VirtualClock().advance_to(bad)  # type: ignore[arg-type]


def test_numpy_whole_numbers_are_times() -> None:
    clock = VirtualClock()
    clock.advance_to(np.int64(12))
    assert clock.now_ns() == 12 and type(clock.now_ns()) is int


def test_the_monotonic_clock_does_not_run_backwards_and_a_past_time_returns_at_once() -> None:
    clock = MonotonicClock()
    first = clock.now_ns()
    clock.sleep_until_ns(first - 10**9)  # long past: no wait
    assert clock.now_ns() >= first
