"""The outcome of a check, a step or a plan: one word with a meaning, as OpenHTF has it.

Check:  PASS, MARGINAL (passes, close to a limit), FAIL, ERROR (could not be
        computed), SKIPPED (never reached), INFO (a `role: finding` check: the
        value is recorded and cannot fail the plan).
Step:   PASS, FAIL, ERROR, TIMEOUT, SKIPPED.
Plan:   PASS, FAIL, ERROR, TIMEOUT, ABORTED, SKIPPED (the plan's link needs a program this
        machine lacks, e.g. QEMU: nothing ran; `hil run` exits 0 for it).
"""
from __future__ import annotations

from enum import Enum


class Outcome(str, Enum):
    PASS = "PASS"
    MARGINAL = "MARGINAL"
    FAIL = "FAIL"
    ERROR = "ERROR"
    TIMEOUT = "TIMEOUT"
    ABORTED = "ABORTED"
    SKIPPED = "SKIPPED"
    INFO = "INFO"          # a finding's check: measured and recorded, never judged


    def __str__(self) -> str:
        return self.value

    @property
    def passed(self) -> bool:
        return self in (Outcome.PASS, Outcome.MARGINAL, Outcome.INFO)


CHECK_OUTCOMES = (Outcome.PASS, Outcome.MARGINAL, Outcome.FAIL, Outcome.ERROR, Outcome.SKIPPED,
                  Outcome.INFO)
STEP_OUTCOMES = (Outcome.PASS, Outcome.FAIL, Outcome.ERROR, Outcome.TIMEOUT, Outcome.SKIPPED)
PLAN_OUTCOMES = (Outcome.PASS, Outcome.FAIL, Outcome.ERROR, Outcome.TIMEOUT, Outcome.ABORTED,
                 Outcome.SKIPPED)


__all__ = ["Outcome", "CHECK_OUTCOMES", "STEP_OUTCOMES", "PLAN_OUTCOMES"]
