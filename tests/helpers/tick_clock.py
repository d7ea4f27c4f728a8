"""A stand-in for the ``time`` module in tests of measured durations."""

from __future__ import annotations


class TickClock:
    """``perf_counter`` that advances by one second at each reading, so a duration
    measured between two readings is a count of readings."""

    def __init__(self) -> None:
        self.now = 100.0

    def perf_counter(self) -> float:
        self.now += 1.0
        return self.now
