"""One watchdog and one answer wait, shared by both clocks (lockstep and real time).

The board is expected to answer every SAMPLE. The watchdog trips (SPEC.md 2.8.2) when
`periods` consecutive control periods were missed, or when `seconds` of wall time passed since
the streak of misses began (the SAMPLE of its first period went out), whichever comes first;
the session then safe-states the plant and ends with ERROR.

Every wait has one deadline, fixed when the awaited frame goes out: frames that are not the
answer (HEARTBEAT, TELEMETRY, a flood of garbage) are handled but never extend it, and a flood
is read for at most one more wait length after the deadline (SPEC.md 2.8).
"""
from __future__ import annotations

import time
from typing import Any, Callable


class Watchdog:
    """Counts consecutive unanswered periods; `missed` returns the reason once it trips."""

    def __init__(self, periods: int, seconds: float | None = None,
                 clock: Callable[[], float] = time.monotonic):
        if periods < 1:
            raise ValueError(f"watchdog_periods must be at least 1, got {periods}")
        if seconds is not None and seconds <= 0:
            raise ValueError(f"watchdog_s must be positive, got {seconds}")
        self.periods = periods
        self.seconds = seconds
        self.consecutive = 0
        self.tripped_by: str | None = None     # "periods" | "seconds" once tripped
        self._clock = clock
        self._since: float | None = None

    def answered(self) -> None:
        self.consecutive = 0
        self._since = None

    @property
    def elapsed_s(self) -> float:
        return 0.0 if self._since is None else self._clock() - self._since

    def missed(self, count: int = 1, since: float | None = None) -> str | None:
        """Records `count` more unanswered periods; the reason when the watchdog trips.

        since: when the first of them began (its SAMPLE went out); default now."""
        self.consecutive += count
        now = self._clock()
        if self._since is None:
            self._since = now if since is None else since
        if self.consecutive >= self.periods:
            self.tripped_by = "periods"
            return f"no GATES/DUTY for {self.consecutive} consecutive periods"
        if self.seconds is not None and now - self._since >= self.seconds:
            self.tripped_by = "seconds"
            return (f"no GATES/DUTY for {now - self._since:.3f} s of wall time "
                    f"({self.consecutive} periods)")
        return None


def await_answer(link: Any, is_answer: Callable[[Any], bool], timeout_s: float,
                 dispatch: Callable[[Any], None], clock: Callable[[], float] = time.monotonic,
                 check: Callable[[], None] | None = None, slice_s: float | None = None):
    """Receives until `is_answer(msg)`, dispatching everything else, within one deadline.

    Returns the answer, or None when the deadline passed. Other traffic never extends the
    deadline; a flood is read for at most one more `timeout_s` after it. A timeout of 0 takes
    only what is already there (the in-process stub). `check` runs after every receive (it
    may raise: a frame of another protocol version ends a HELLO wait at once); `slice_s`
    bounds each receive so that `check` runs even while only bad frames arrive."""
    deadline = clock() + timeout_s
    remaining = timeout_s
    while True:
        wait = remaining if remaining > 0.0 else 0.0
        if slice_s is not None and wait > slice_s:
            wait = slice_s
        msg = link.recv(wait)
        if check is not None:
            check()
        if msg is None:
            remaining = deadline - clock()
            if remaining > 0.0:
                continue
            return None
        if is_answer(msg):
            return msg
        dispatch(msg)
        remaining = deadline - clock()
        if remaining <= 0.0:
            # one last look without waiting: the answer may already be queued
            msg = link.recv(0.0)
            while msg is not None:
                if check is not None:
                    check()
                if is_answer(msg):
                    return msg
                dispatch(msg)
                # a flood: stop reading, the wait is lost (an in-process queue, wait 0, is finite)
                if timeout_s > 0.0 and deadline + timeout_s < clock():
                    return None
                msg = link.recv(0.0)
            return None
