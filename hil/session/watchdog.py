"""One watchdog and one answer wait, shared by both clocks (lockstep and real time).

The board is expected to answer every SAMPLE. The watchdog trips when it has not for
`periods` consecutive control periods, or, when `seconds` is given, for that long on the wall
clock, whichever comes first; the session then safe-states the plant and ends with ERROR.

The answer wait (lockstep) has one deadline, fixed when the SAMPLE goes out: frames that are
not the answer (HEARTBEAT, TELEMETRY, a flood of garbage) are handled but never extend it, so
a board that talks without answering cannot hold a run forever (issue 13, item 1).
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
        self.periods = periods
        self.seconds = seconds
        self.consecutive = 0
        self._clock = clock
        self._since: float | None = None

    def answered(self) -> None:
        self.consecutive = 0
        self._since = None

    def missed(self, count: int = 1) -> str | None:
        """Records `count` more unanswered periods; the reason when the watchdog trips."""
        self.consecutive += count
        now = self._clock()
        if self._since is None:
            self._since = now
        if self.consecutive >= self.periods:
            return f"no GATES for {self.consecutive} consecutive periods"
        if self.seconds is not None and now - self._since >= self.seconds:
            return (f"no GATES for {now - self._since:.3f} s of wall time "
                    f"({self.consecutive} periods)")
        return None


def await_answer(link: Any, is_answer: Callable[[Any], bool], timeout_s: float,
                 dispatch: Callable[[Any], None], clock: Callable[[], float] = time.monotonic):
    """Receives until `is_answer(msg)`, dispatching everything else, within one deadline.

    Returns the answer, or None when the deadline passed. Other traffic never extends the
    deadline; a timeout of 0 takes only what is already there (the in-process stub)."""
    deadline = clock() + timeout_s
    remaining = timeout_s
    while True:
        msg = link.recv(remaining if remaining > 0.0 else 0.0)
        if msg is None:
            return None
        if is_answer(msg):
            return msg
        dispatch(msg)
        remaining = deadline - clock()
        if remaining <= 0.0 and timeout_s > 0.0:
            # one last look without waiting: the answer may already be queued
            msg = link.recv(0.0)
            while msg is not None:
                if is_answer(msg):
                    return msg
                dispatch(msg)
                if deadline + timeout_s < clock():   # a flood: stop reading, the period is lost
                    return None
                msg = link.recv(0.0)
            return None
