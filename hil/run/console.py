"""What happens during a run, said on the console as it happens.

A session records its events (hil.session.BenchSession.event_listeners); `EventConsole` is a
listener that prints the notable ones: board FAULTs, shoot-through, watchdog trips, missed
SAMPLE answers (a link-fault burst shows as a run of them), real-time deadline misses, a
failed link, a refusal, an injected fault. Each kind is printed at once the first time, then
at most once per `interval_s` of wall time with the count held back meanwhile ("... and 37
more in the last 1.0 s"); whatever is still held back is printed by `tick()` once the interval
has passed and by `close()` at the end of the plan. So a burst of thousands of missed
answers costs a few lines, and nothing that happened goes unsaid.

The session itself already warns once, on stderr, of the first board FAULT and the first
shoot-through (so does a Python user of `Bench`), naming the plan and profile of a plan run;
the console does not repeat those first ones. `hil run` sets the console's `prefix` to name
the plan and profile of each run too ("hil: speed-step [paper]: t = ...").
"""
from __future__ import annotations

import sys
import time
from collections.abc import Callable

from configfile.dataclass_methods import dataclass

#: kind -> the words for one of it (the events of hil.session.bench_session and realtime)
LABELS = {
    "board_fault": "board FAULT",
    "shoot_through": "shoot-through",
    "watchdog": "watchdog trip",
    "missed": "missed SAMPLE answer",
    "deadline_miss": "real-time deadline miss",
    "link_failed": "link failure",
    "refused": "refusal by the board",
    "fault": "fault",
}
#: a fault event's action, in words
_ACTIONS = {"inject": "injected", "lift": "lifted"}
#: kinds whose first occurrence the session prints itself (hil: warning: ...)
SESSION_PRINTS_FIRST = frozenset({"board_fault", "shoot_through"})


def describe(t_s: float, kind: str, data: dict) -> str:
    """One event in a line: when, what, and the fields that say which."""
    label = _label(kind, data)
    details = []
    for key in ("code", "period", "samples_sent", "late_us", "legs", "reason"):
        if key in data:
            value = data[key]
            if isinstance(value, float):
                value = f"{value:.4g}"
            elif isinstance(value, (list, tuple)):
                value = ",".join(map(str, value))
            details.append(f"{key} {value}")
    text = f"t = {t_s:.6f} s: {label}"
    return f"{text} ({'; '.join(details)})" if details else text


def _label(kind: str, data: dict) -> str:
    if kind == "fault":
        return f"fault {data.get('name', '?')} {_ACTIONS.get(data.get('action'), data.get('action', ''))}"
    return LABELS.get(kind, kind)


@dataclass
class _Kind:
    """One kind of event: when it was last printed and what is held back since."""

    last_print: float
    label: str = ""
    held: int = 0
    latest: str = ""


class EventConsole:
    """A session event listener that prints notable events, rate-limited per kind."""

    def __init__(self, write: Callable[[str], None] | None = None, interval_s: float = 1.0,
                 clock: Callable[[], float] = time.monotonic, prefix: str = "hil: "):
        self._write = write or (lambda text: print(text, file=sys.stderr, flush=True))
        self.interval_s = interval_s
        self._clock = clock
        self.prefix = prefix
        self._kinds: dict[str, _Kind] = {}
        self.printed = 0              # lines written (tests count them)

    def _emit(self, text: str) -> None:
        self.printed += 1
        self._write(self.prefix + text)

    def __call__(self, t_s: float, kind: str, data: dict) -> None:
        if kind not in LABELS:
            return
        now = self._clock()
        text = describe(t_s, kind, data)
        key = (kind, data.get("action")) if kind == "fault" else (kind, None)
        state = self._kinds.get(key)
        if state is None:
            self._kinds[key] = _Kind(last_print=now, label=_label(kind, data))
            if kind not in SESSION_PRINTS_FIRST:
                self._emit(text)
            return
        if now - state.last_print >= self.interval_s:
            self._emit(self._with_held(text, state))
            state.held, state.last_print = 0, now
        else:
            state.held += 1
            state.latest = text

    def _with_held(self, text: str, state: _Kind) -> str:
        if state.held == 0:
            return text
        return f"{text}; and {state.held} more since the last line"

    def tick(self) -> None:
        """Prints what has been held back longer than the interval (call it now and then)."""
        now = self._clock()
        for state in self._kinds.values():
            if state.held and now - state.last_print >= self.interval_s:
                self._emit(self._summary(state))
                state.held, state.last_print = 0, now

    def close(self) -> None:
        """Prints everything still held back; the console can serve the next plan after."""
        for state in self._kinds.values():
            if state.held:
                self._emit(self._summary(state))
        self._kinds.clear()

    @staticmethod
    def _summary(state: _Kind) -> str:
        return f"{state.held} more: {state.label} (the last at {state.latest})"
