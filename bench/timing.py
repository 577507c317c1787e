"""What the bench scripts share: the best wall time of a few calls."""

from __future__ import annotations

import time


def timed(function, repeat: int = 1):
    """The result and the best wall time of `repeat` calls."""
    best = float("inf")
    for _ in range(repeat):
        begin = time.perf_counter()
        result = function()
        best = min(best, time.perf_counter() - begin)
    return result, best
