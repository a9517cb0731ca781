"""Outcomes at three levels (check, step, plan) and the run record.

Check:  PASS, MARGINAL (passes, close to a limit), FAIL, ERROR (could not be
        computed: a missing signal, an empty window), SKIPPED (never reached).
Step:   PASS, FAIL (a check step that failed), ERROR, TIMEOUT (a wait_until
        whose condition did not hold in time), SKIPPED (not reached).
Plan:   PASS, FAIL (a check failed, or the board tripped where the plan did not expect
        it: a FAULT or a shoot-through ends the plan at once, the trip named), ERROR (the bench or the board failed, or a
        check could not be computed), TIMEOUT (a step's own time limit or the
        plan's wall-clock budget), ABORTED (Ctrl-C), SKIPPED (the plan's link needs a
        program this machine lacks, such as qemu-system-arm: nothing ran), each with its reason.

A plan with MARGINAL checks and no failure is PASS; the report counts them.
The run record (`PlanResult.to_json`) is plain data for other tools.
"""
from __future__ import annotations

import math
from dataclasses import field
from enum import Enum
from typing import Any

from configfile.dataclass_methods import dataclass
from hil.plans.limits import Limits
from hil.plans.verdict import CHECK_OUTCOMES, PLAN_OUTCOMES, STEP_OUTCOMES, Outcome




def _num(x: float | None) -> float | None | str:
    """JSON has no NaN or infinity: they travel as strings."""
    if x is None:
        return None
    x = float(x)
    if math.isfinite(x):
        return x
    return "nan" if math.isnan(x) else ("inf" if x > 0 else "-inf")


def _from_num(x: Any) -> float | None:
    return None if x is None else float(x)


@dataclass(frozen=True)
class CheckResult:
    """One check's verdict: measured value in the limits' unit, and where it was measured."""

    name: str
    kind: str
    outcome: Outcome
    measured: float | None       # in `unit`; None when not computed
    unit: str                    # the limits' unit (the measurement's own when no limits)
    limits: "Limits | None"
    message: str
    window: tuple[float, float] | None = None   # simulated seconds
    signals: tuple[str, ...] = ()
    line: int | None = None      # the check's line in the plan
    details: dict[str, Any] = field(default_factory=dict)  # secondary values and plot hints
    plot: bool = True            # the plan wants this check's window plotted
    role: str = "acceptance"     # acceptance | regression | finding (hil.plans.format.CHECK_ROLES)
    note: str = ""               # the plan's note on the check (where a regression bound came from)
    # The formulas the limits came from: bound (low/high/marginal) -> Derivation as JSON
    # (formula, value, unit, inputs), hil.plans.formula.
    formulas: dict[str, Any] = field(default_factory=dict)

    def to_json(self) -> dict:
        return {
            "name": self.name, "kind": self.kind, "outcome": self.outcome.value,
            "role": self.role, "note": self.note,
            "measured": _num(self.measured), "unit": self.unit,
            "limits": None if self.limits is None else self.limits.to_json(),
            "limit_formulas": dict(self.formulas),
            "message": self.message,
            "window": None if self.window is None else [_num(self.window[0]), _num(self.window[1])],
            "signals": list(self.signals), "line": self.line, "plot": self.plot,
            # Keys starting with "_" hold plot data (arrays) for the report only.
            "details": _jsonable({k: v for k, v in self.details.items() if not k.startswith("_")}),
        }

    @classmethod
    def from_json(cls, data: dict) -> "CheckResult":
        window = data.get("window")
        return cls(name=data["name"], kind=data["kind"], outcome=Outcome(data["outcome"]),
                   measured=_from_num(data.get("measured")), unit=data["unit"],
                   limits=None if data.get("limits") is None else Limits.from_json(data["limits"]),
                   message=data.get("message", ""),
                   window=None if window is None else (float(window[0]), float(window[1])),
                   signals=tuple(data.get("signals", ())), line=data.get("line"),
                   details=dict(data.get("details", {})), plot=bool(data.get("plot", True)),
                   role=data.get("role", "acceptance"), note=data.get("note", ""),
                   formulas=dict(data.get("limit_formulas") or {}))


@dataclass(frozen=True)
class StepResult:
    """One step as it ran: outcome, line and simulated start and end."""

    index: int
    kind: str
    outcome: Outcome
    line: int | None = None
    start_s: float | None = None   # simulated time the step began
    end_s: float | None = None
    message: str = ""

    def to_json(self) -> dict:
        return {"index": self.index, "kind": self.kind, "outcome": self.outcome.value,
                "line": self.line, "start_s": _num(self.start_s), "end_s": _num(self.end_s),
                "message": self.message}

    @classmethod
    def from_json(cls, data: dict) -> "StepResult":
        return cls(index=data["index"], kind=data["kind"], outcome=Outcome(data["outcome"]),
                   line=data.get("line"), start_s=_from_num(data.get("start_s")),
                   end_s=_from_num(data.get("end_s")), message=data.get("message", ""))


@dataclass(frozen=True)
class PlanResult:
    """One plan run on one profile: its outcome, steps, checks and the run's record."""

    plan_name: str
    source: str
    outcome: Outcome
    reason: str
    steps: tuple[StepResult, ...] = ()
    checks: tuple[CheckResult, ...] = ()
    started_at: str = ""              # wall clock, ISO 8601
    ended_at: str = ""
    sim_duration_s: float = 0.0
    wall_duration_s: float = 0.0
    link: str = ""
    mode: str = ""
    log_path: str | None = None
    description: str = ""
    marks: dict[str, float] = field(default_factory=dict)
    extra: dict[str, Any] = field(default_factory=dict)  # link counters, real-time stats, ...
    profile: str = ""                 # the bench profile it ran on (a name, or a path as written)

    def counts(self) -> dict[str, int]:
        out = {o.value: 0 for o in CHECK_OUTCOMES}
        for c in self.checks:
            out[c.outcome.value] = out.get(c.outcome.value, 0) + 1
        return out

    def to_json(self) -> dict:
        return {
            "plan": self.plan_name, "profile": self.profile, "source": self.source,
            "outcome": self.outcome.value,
            "reason": self.reason, "description": self.description,
            "started_at": self.started_at, "ended_at": self.ended_at,
            "sim_duration_s": _num(self.sim_duration_s), "wall_duration_s": _num(self.wall_duration_s),
            "link": self.link, "mode": self.mode, "log_path": self.log_path,
            "marks": {k: _num(v) for k, v in self.marks.items()},
            "counts": self.counts(),
            "steps": [s.to_json() for s in self.steps],
            "checks": [c.to_json() for c in self.checks],
            "extra": _jsonable(self.extra),
        }

    @classmethod
    def from_json(cls, data: dict) -> "PlanResult":
        return cls(plan_name=data["plan"], source=data["source"], outcome=Outcome(data["outcome"]),
                   reason=data.get("reason", ""),
                   steps=tuple(StepResult.from_json(s) for s in data.get("steps", ())),
                   checks=tuple(CheckResult.from_json(c) for c in data.get("checks", ())),
                   started_at=data.get("started_at", ""), ended_at=data.get("ended_at", ""),
                   sim_duration_s=_from_num(data.get("sim_duration_s")) or 0.0,
                   wall_duration_s=_from_num(data.get("wall_duration_s")) or 0.0,
                   link=data.get("link", ""), mode=data.get("mode", ""),
                   log_path=data.get("log_path"), description=data.get("description", ""),
                   marks={k: float(v) for k, v in data.get("marks", {}).items()},
                   extra=dict(data.get("extra", {})), profile=data.get("profile", ""))


def plan_outcome(steps: tuple[StepResult, ...] | list[StepResult],
                 checks: tuple[CheckResult, ...] | list[CheckResult],
                 error: str | None = None, aborted: str | None = None,
                 timeout: str | None = None, skipped: str | None = None,
                 tripped: str | None = None) -> tuple[Outcome, str]:
    """The plan's outcome and reason from its steps and checks.

    Precedence: ABORTED (the user stopped it) > SKIPPED (its link could not exist on this
    machine, so nothing ran) > ERROR (bench or board failed) > FAIL by a trip (`tripped`: the
    board's FAULT or shoot-through ended the plan; the cause comes first) > ERROR (an
    uncomputable check) > TIMEOUT > FAIL > PASS.
    """
    if aborted is not None:
        return Outcome.ABORTED, aborted
    if skipped is not None:
        return Outcome.SKIPPED, skipped
    if error is not None:
        return Outcome.ERROR, error
    if tripped is not None:
        return Outcome.FAIL, tripped
    errored = [c for c in checks if c.outcome is Outcome.ERROR]
    if errored:
        return Outcome.ERROR, f"check '{errored[0].name}' could not be computed: {errored[0].message}"
    errored_steps = [s for s in steps if s.outcome is Outcome.ERROR]
    if errored_steps:
        s = errored_steps[0]
        return Outcome.ERROR, f"step {s.index + 1} ({s.kind}, line {s.line}): {s.message}"
    if timeout is not None:
        return Outcome.TIMEOUT, timeout
    timed_out = [s for s in steps if s.outcome is Outcome.TIMEOUT]
    if timed_out:
        s = timed_out[0]
        return Outcome.TIMEOUT, f"step {s.index + 1} ({s.kind}, line {s.line}): {s.message}"
    failed = [c for c in checks if c.outcome is Outcome.FAIL]
    if failed:
        names = ", ".join(f"'{c.name}'" + (" (regression)" if c.role == "regression" else "")
                          for c in failed[:3])
        more = f" and {len(failed) - 3} more" if len(failed) > 3 else ""
        return Outcome.FAIL, f"{len(failed)} check(s) failed: {names}{more}"
    marginal = sum(1 for c in checks if c.outcome is Outcome.MARGINAL)
    passed = sum(1 for c in checks if c.outcome is Outcome.PASS)
    info = sum(1 for c in checks if c.outcome is Outcome.INFO)
    note = f", {marginal} marginal" if marginal else ""
    note += f", {info} finding(s) recorded" if info else ""
    return Outcome.PASS, f"{passed + marginal} check(s) passed{note}"


def _jsonable(value: Any) -> Any:
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    if isinstance(value, Enum):
        return value.value
    if isinstance(value, bool) or value is None or isinstance(value, str):
        return value
    if isinstance(value, int):
        return value
    if hasattr(value, "item"):          # numpy scalars
        return _jsonable(value.item())
    if isinstance(value, float):
        return _num(value)
    return str(value)


__all__ = ["Outcome", "CheckResult", "StepResult", "PlanResult", "plan_outcome",
           "CHECK_OUTCOMES", "STEP_OUTCOMES", "PLAN_OUTCOMES"]
