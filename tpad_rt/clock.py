"""Clocks the timing code reads: the host's monotonic clock, or a virtual one that tests advance.

API map
-------
Clock
    the protocol: ``now_ns() -> int`` (ns) and ``sleep_until_ns(t_ns)``
MonotonicClock()
    CLOCK_MONOTONIC (``time.monotonic_ns``) and real sleeps: the production clock
VirtualClock(start_ns=0)
    a discrete-event clock: time moves only when someone sleeps on it or calls
    ``advance_to(t_ns)``, and the events scheduled with ``at(t_ns, action)`` run in time order
    (ties in the order scheduled) as it passes them, each with the clock reading its time

Every driver that paces itself takes a Clock, so its behaviour in time (pacing, skip-ahead,
watchdogs, stop ramps) is tested on a VirtualClock, deterministically, with no sleep and no
threshold on the host's scheduling (docs/testing.md "Three tiers").
"""

from __future__ import annotations

import heapq
import numbers
import time
from collections.abc import Callable
from typing import Protocol


class Clock(Protocol):
    """What a paced loop reads and waits on."""

    def now_ns(self) -> int:
        """The time now (ns)."""

    def sleep_until_ns(self, t_ns: int) -> None:
        """Return at ``t_ns`` (ns) or later; at once when it has passed."""


class MonotonicClock:
    """The host's CLOCK_MONOTONIC, with real sleeps."""

    def now_ns(self) -> int:
        """CLOCK_MONOTONIC (ns)."""
        return time.monotonic_ns()

    def sleep_until_ns(self, t_ns: int) -> None:
        """Sleep until CLOCK_MONOTONIC reaches ``t_ns`` (ns)."""
        wait_ns = t_ns - time.monotonic_ns()
        if wait_ns > 0:
            time.sleep(wait_ns * 1e-9)


class VirtualClock:
    """A clock that only moves when told to; single-threaded (one loop drives it).

    ``sleep_until_ns`` advances it (running the events due on the way), so a loop written
    for :class:`MonotonicClock` runs on it unchanged, as fast as the host computes.
    Raises ValueError for a time that is not a whole number of ns.
    """

    def __init__(self, start_ns: int = 0):
        self._now_ns = _whole_ns(start_ns)
        self._events: list[tuple[int, int, Callable[[], None]]] = []
        self._scheduled = 0

    def now_ns(self) -> int:
        """The virtual time (ns)."""
        return self._now_ns

    def now_s(self) -> float:
        """The virtual time (s)."""
        return self._now_ns * 1e-9

    def at(self, t_ns: int, action: Callable[[], None]) -> None:
        """Run ``action()`` when the clock passes ``t_ns`` (ns; at the next advance if that is past)."""
        heapq.heappush(self._events, (max(_whole_ns(t_ns), self._now_ns), self._scheduled, action))
        self._scheduled += 1

    def advance_to(self, t_ns: int) -> None:
        """Move to ``t_ns`` (ns; never backwards), running each event due on the way at its own time."""
        target_ns = max(_whole_ns(t_ns), self._now_ns)
        while self._events and self._events[0][0] <= target_ns:
            when_ns, _, action = heapq.heappop(self._events)
            self._now_ns = max(when_ns, self._now_ns)
            action()
        self._now_ns = target_ns

    def advance_by(self, delta_ns: int) -> None:
        """Move ``delta_ns`` (ns, not negative) ahead."""
        if _whole_ns(delta_ns) < 0:
            raise ValueError(f"VirtualClock.advance_by: a negative step, {delta_ns} ns")
        self.advance_to(self._now_ns + delta_ns)

    def sleep_until_ns(self, t_ns: int) -> None:
        """Advance to ``t_ns`` (ns), as a sleep until then would."""
        self.advance_to(t_ns)

    def next_event_ns(self) -> int | None:
        """When the next scheduled event is due (ns), None if none is."""
        return self._events[0][0] if self._events else None


def _whole_ns(t_ns: int) -> int:
    """``t_ns`` as an int (a NumPy integer too); ValueError for anything else (a bool, a float, text)."""
    if isinstance(t_ns, numbers.Integral) and not isinstance(t_ns, bool):
        return int(t_ns)
    raise ValueError(f"VirtualClock: a time must be a whole number of ns, got {t_ns!r}")


__all__ = ["Clock", "MonotonicClock", "VirtualClock"]
