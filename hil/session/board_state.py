"""The board's controller state, as its STATUS messages tell it (SPEC.md 2 item 5, 6.8, 9.4).

A board with a start-up phase (sensor alignment, offset calibration, identification) reports
STARTING when enabled and RUNNING once it controls; one without goes IDLE -> RUNNING. The
board is *ready* from the period its STATUS(RUNNING) names. This module keeps the latest state,
every change (for the run record), the moment the board last became ready since the bench last
enabled it, and the step signals `board.state` and `board.ready` on the period grid (held
between changes, recorder.step_value).

The STATUS period comes from the board: it is taken as the moment of the change when it lies
between the previous change and the period the bench is at (one ahead: a COMMAND's change
applies from the next SAMPLE); otherwise the period the STATUS arrived in is used, and the
change is marked `period_from_board: False`.
"""
from __future__ import annotations

from protocol.messages import ControllerState, FaultCode

#: Step signals this module records (hil/plans/signals.py lists them for plans).
STATE_SIGNAL = "board.state"
READY_SIGNAL = "board.ready"


def state_name(state: int | None) -> str:
    """SPEC 9.4's name of a state byte; an unknown value is named with its number."""
    if state is None:
        return "no STATUS received"
    try:
        return ControllerState(state).name
    except ValueError:
        return f"state {state} (unknown to this bench)"


def fault_name(code: int) -> str:
    try:
        return FaultCode(code).name
    except ValueError:
        return "UNKNOWN"


class BoardState:
    """Latest STATUS state, its changes and the ready moment of one session."""

    def __init__(self, period_s: float, recorder=None):
        self.period_s = period_s
        self.recorder = recorder
        self.state: int | None = None          # None until the first STATUS
        self.fault_code = 0
        self.since_period: int | None = None   # the period of the latest change
        self.ready_period: int | None = None   # ready since this period (None: not ready)
        self.changes: list[dict] = []          # every STATUS that changed the state
        self._last_row = 0                     # the latest period a step signal changed at
        self._enabled_unseen = False           # enable changed while ready, no STATUS since

    @property
    def ready(self) -> bool:
        return self.ready_period is not None

    @property
    def ready_t_s(self) -> float | None:
        return None if self.ready_period is None else self.ready_period * self.period_s

    @property
    def faulted(self) -> bool:
        return self.state == ControllerState.FAULT

    def enable_changed(self, period: int) -> None:
        """The bench enables or disables the board at `period`: whatever ready it was before no
        longer holds (disabled it stops; enabled its start-up runs again), before its STATUS
        says so; the next STATUS(RUNNING) makes it ready."""
        if self.ready_period is not None:
            self.ready_period = None
            self._enabled_unseen = True
            self._record(max(period, self._last_row))

    def on_status(self, state: int, fault_code: int, period: int, arrival_period: int) -> None:
        """A STATUS from the board, received while the bench is at `arrival_period`."""
        self.fault_code = fault_code
        if state == self.state and not (state == ControllerState.RUNNING and self.ready_period is None):
            return                     # a repeat (SHUTDOWN's, a resend): no change
        self._enabled_unseen = False
        from_board = self._last_row <= period <= arrival_period + 1
        at = period if from_board else max(arrival_period, self._last_row)
        self.state = state
        self.since_period = at
        if state == ControllerState.RUNNING:
            if self.ready_period is None:
                self.ready_period = at
        else:
            self.ready_period = None
        change = {"t_s": at * self.period_s, "period": at, "state": state,
                  "name": state_name(state), "fault_code": fault_code,
                  "ready": state == ControllerState.RUNNING}
        if not from_board:
            change["period_from_board"] = False
            change["board_period"] = period
        self.changes.append(change)
        self._record(at)

    def _record(self, period: int) -> None:
        """Both step signals from `period` on (never before a change already recorded)."""
        self._last_row = period
        if self.recorder is not None:
            self.recorder.step_value(STATE_SIGNAL, period, self.state if self.state is not None else 0)
            self.recorder.step_value(READY_SIGNAL, period, 1.0 if self.ready else 0.0)

    def describe(self) -> str:
        """The state now, for a message: 'STARTING since t = 0.01 s (period 200)'."""
        if self.state is None:
            return "no STATUS received from the board (SPEC 2 item 5: a board sends one on each change)"
        text = f"{state_name(self.state)} since t = {self.since_period * self.period_s:.6g} s " \
               f"(period {self.since_period})"
        if self.fault_code:
            text += f", fault code {self.fault_code} {fault_name(self.fault_code)}"
        if self._enabled_unseen:
            text += "; no state change reported since the bench last enabled or disabled it"
        return text


__all__ = ["BoardState", "STATE_SIGNAL", "READY_SIGNAL", "state_name", "fault_name"]
