"""The stall watchdog of a stream driven by someone else's thread (PortAudio's): :class:`StallWatch`.

It watches a count that the stream's callback advances (the callbacks made) and says when the
count has stood still for the stall limit on a :class:`tpad_rt.clock.Clock`. The clock is read
before the count and again when the count has advanced, so the stillness it measures never
exceeds the time without a callback however late the watcher itself runs (a watcher held from
the GIL for seconds while callbacks went on sees an advance, not a stall). Tested on a
:class:`tpad_rt.clock.VirtualClock` (tests/test_stall.py).
"""

from __future__ import annotations

from collections.abc import Callable

from tpad_rt.clock import Clock


class StallWatch:
    """Stillness of a count on ``clock``: stalled once it has not advanced for ``limit_ns`` (ns, > 0).

    Raises ValueError for a limit that is not a positive number of ns.
    """

    def __init__(self, limit_ns: int, clock: Clock):
        if isinstance(limit_ns, bool) or not isinstance(limit_ns, int) or limit_ns <= 0:
            raise ValueError(f"StallWatch: the limit must be a positive whole number of ns, got {limit_ns!r}")
        self.limit_ns = limit_ns
        self.clock = clock
        self._seen_count: int | None = None
        self._seen_at_ns = clock.now_ns()

    def still_for_ns(self, read_count: Callable[[], int]) -> int | None:
        """Read the count (``read_count()``); the time (ns) it has stood still when that reaches the limit,
        else None (it advanced, or has stood still for less)."""
        now_ns = self.clock.now_ns()
        count = read_count()
        if count != self._seen_count:
            self._seen_count, self._seen_at_ns = count, self.clock.now_ns()
            return None
        still_ns = now_ns - self._seen_at_ns
        return still_ns if still_ns >= self.limit_ns else None


__all__ = ["StallWatch"]
