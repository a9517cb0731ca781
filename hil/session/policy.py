"""How the bench talks to a board: waits, tries, resends and the watchdog, with the defaults
of protocol/SPEC.md section 2.8. A bench profile's `session` section overrides any of them;
its schema (JSON Schema, configfile.schema) is checked when the profile loads, with the file,
line and key of a bad value."""
from __future__ import annotations

from dataclasses import fields
from typing import Any

from configfile.dataclass_methods import dataclass
from configfile.schema import NON_NEGATIVE, POSITIVE, POSITIVE_INT, obj

CAPABILITY_NAMES = ("GATES", "DUTY", "TELEMETRY", "CAN", "DUTY_LEGS")  # bit i = name i (SPEC 9.1)


@dataclass(frozen=True)
class SessionPolicy:
    """SPEC 2.8's table; seconds are wall time."""

    hello_wait_s: float = 1.0          # per HELLO sent
    hello_tries: int = 3
    param_wait_s: float = 1.0          # per PARAM_SET or PARAM_GET sent
    param_tries: int = 3
    answer_wait_periods: int = 2       # lockstep answer wait: max(periods * T, min_s)
    answer_wait_min_s: float = 0.1
    answer_resends: int = 3            # lockstep: resends of SAMPLE(k) before k is missed
    watchdog_periods: int = 20
    watchdog_s: float = 2.0
    require_capabilities: tuple[str, ...] = ()

    def answer_wait_s(self, period_s: float) -> float:
        return max(self.answer_wait_periods * period_s, self.answer_wait_min_s)

    def effective_watchdog_s(self, period_s: float) -> float:
        """SPEC 2.8.2: never shorter than one period's whole resend cycle."""
        return max(self.watchdog_s, (1 + self.answer_resends) * self.answer_wait_s(period_s))

    @classmethod
    def from_profile(cls, profile) -> "SessionPolicy":
        values: dict[str, Any] = dict(getattr(profile, "session", {}) or {})
        if "require_capabilities" in values:
            values["require_capabilities"] = tuple(values["require_capabilities"])
        return cls(**values)


SESSION_SCHEMA = obj({
    "hello_wait_s": POSITIVE, "hello_tries": POSITIVE_INT,
    "param_wait_s": POSITIVE, "param_tries": POSITIVE_INT,
    "answer_wait_periods": POSITIVE_INT, "answer_wait_min_s": NON_NEGATIVE,
    "answer_resends": {"type": "integer", "minimum": 0, "maximum": 100},
    "watchdog_periods": POSITIVE_INT, "watchdog_s": POSITIVE,
    "require_capabilities": {"type": "array", "items": {"enum": list(CAPABILITY_NAMES)},
                             "uniqueItems": True},
})
assert set(SESSION_SCHEMA["properties"]) == {f.name for f in fields(SessionPolicy)}
