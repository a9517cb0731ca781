"""Test plans: YAML files validated completely before anything runs.

A plan is data, never code: it is loaded with the safe loader of
configfile.source, its structure checked against JSON schemas (unknown keys,
wrong types, out-of-range numbers), then its meaning checked (known signals,
check kinds, units, parameter and fault names; marks defined before use;
check names unique). Every error is a ConfigError naming the file, the line
and the key, and saying what was expected. test_plans/README.md documents
every key.

The result is a frozen `Plan` with one frozen dataclass per step kind, each
carrying its index and source line, for the runner (hil.run.runner) to execute.
"""
from __future__ import annotations

import math
import re
from collections.abc import Callable, Iterable, Mapping
from dataclasses import field
from pathlib import Path
from types import MappingProxyType
from typing import Any, ClassVar, Union


from configfile.dataclass_methods import dataclass
from hil.plans.checks import CHECK_KINDS, STATISTICS, ArgSpec, CheckKind, result_unit
from hil.plans.formula import Derivation
from hil.plans.limits import Limits
from hil.plans.signals import SENSOR_SET_SIGNALS, SIGNAL_CATALOG
from hil.plans.units import Quantity, UnitError, canonical, compatible, unit as lookup_unit
from hil.boards.standard import STANDARD_PARAMS
from configfile.schema import (BOOLEAN, FRACTION, NAME, NON_NEGATIVE, NUMBER, POSITIVE, POSITIVE_INT,
                               SchemaChecker, obj, python_type)
from configfile.source import ConfigError, KeyPath, YamlDocument, format_key, load_yaml, parse_yaml
from hil.control_inputs import UNBOUNDED, ControlInputError, ControlLimits
from hil.faults.catalog import FAULTS, PLANT_PARAMS

# SPEC 8's standard parameters a plan may PARAM_SET on any board that takes them. A board's
# own (vendor) parameters come from its board file: a plan's `param_set` names are checked
# against the board of the run before anything runs (hil.run.runner.check_plan_board).
BOARD_PARAMS: tuple[str, ...] = tuple(n for n, p in STANDARD_PARAMS.items() if not p.read_only)
READ_ONLY_BOARD_PARAMS: tuple[str, ...] = tuple(n for n, p in STANDARD_PARAMS.items()
                                                if p.read_only)
_PARAM_NAME = re.compile(r"^[a-z][a-z0-9_]*$")


# Named bench profiles (plant_rt's default profile is the paper's): "paper" and
# "default" are plant_rt/profiles/paper.yaml; any other name NAME is
# plant_rt/profiles/NAME.yaml when that file exists (e.g. "paper-hardware").
# Anything else in `profile:` / `profiles:` must be a path to a profile file.
PROFILE_NAMES = ("paper", "default")
# A check's role: acceptance (the default: a limit derived from the design, the
# physics or a requirement before the first run), regression (a bound taken from
# a measurement: still fails the plan, shown apart in the report, needs a `note`
# saying where it came from), finding (informs: the value is recorded, outcome
# INFO, it cannot fail the plan; `limits`, if given, state a claim such as the
# paper's, reported as holding or not).
CHECK_ROLES = ("acceptance", "regression", "finding")


def profiles_dir() -> Path:
    import plant_rt.profiles as _profiles

    return Path(_profiles.__file__).resolve().parent


def named_profile_names() -> tuple[str, ...]:
    """Every profile name a plan may use: paper, default, and plant_rt/profiles/*.yaml's stems."""
    extra = sorted(f.stem for f in profiles_dir().glob("*.yaml") if f.stem not in PROFILE_NAMES)
    return PROFILE_NAMES + tuple(extra)


def named_profile_path(name: str) -> Path | None:
    """The file of a named profile; None for the default (paper) profile; KeyError if unknown."""
    if name in PROFILE_NAMES:
        return None
    path = profiles_dir() / f"{name}.yaml"
    if not path.is_file():
        raise KeyError(name)
    return path


@dataclass(frozen=True)
class ProfileRef:
    """One profile a plan runs on: its label (the name, or the path as written) and its file
    (None: plant_rt's default, the paper's)."""

    label: str
    path: Path | None = None


def resolve_profile(value: str, base_dir: Path) -> ProfileRef:
    """A profile name or path (relative to base_dir) -> ProfileRef; ValueError with the reason."""
    if "/" in value or value.endswith((".yaml", ".yml")):
        path = (base_dir / value).resolve()
        if not path.is_file():
            raise ValueError(f"profile file not found: {path}")
        return ProfileRef(value, path)
    try:
        return ProfileRef(value, named_profile_path(value))
    except KeyError:
        raise ValueError(f"unknown profile '{value}': expected one of "
                         f"{', '.join(named_profile_names())} or a path to a profile "
                         f"file (containing '/' or ending in .yaml)") from None
SPEED_SOURCES = ("encoder", "conventional", "ekf")
MODES = ("lockstep", "realtime")
LINK_PATTERN = r"^(stub|stub-pty|stub-can|qemu|serial:.+|can:.+)$"
WAIT_COMPARISONS = ("above", "below", "at_least", "at_most", "within")
LOAD_TYPES = ("constant", "step", "ramp", "table", "speed_proportional")
RESERVED_MARKS = ("start", "now")



# --------------------------------------------------------------------------- #
# Dataclasses                                                                  #
# --------------------------------------------------------------------------- #

@dataclass(frozen=True)
class Window:
    """[mark + offset_s, mark + offset_s + duration_s] or [.., to + to_offset_s] or [.., now].

    ``start`` is t = 0 and ``now`` the time the check step is reached.
    """

    from_mark: str = "start"
    offset_s: float = 0.0
    duration_s: float | None = None
    to_mark: str | None = None
    to_offset_s: float = 0.0

    def resolve(self, marks: Mapping[str, float], now_s: float) -> tuple[float, float]:
        """(t0, t1) in simulated seconds; KeyError for a mark that was not recorded."""
        def at(name: str) -> float:
            if name == "now":
                return now_s
            if name == "start":
                return marks.get("start", 0.0)
            return marks[name]
        t0 = at(self.from_mark) + self.offset_s
        if self.duration_s is not None:
            t1 = t0 + self.duration_s
        elif self.to_mark is not None:
            t1 = at(self.to_mark) + self.to_offset_s
        else:
            t1 = now_s
        return t0, t1

    def marks_used(self) -> tuple[str, ...]:
        return tuple(m for m in (self.from_mark, self.to_mark) if m is not None)

    def describe(self) -> str:
        def term(mark: str, off: float) -> str:
            return mark if off == 0 else f"{mark} {'+' if off > 0 else '-'} {abs(off) * 1e3:g} ms"
        start = term(self.from_mark, self.offset_s)
        if self.duration_s is not None:
            return f"{start} for {self.duration_s * 1e3:g} ms"
        end = term(self.to_mark, self.to_offset_s) if self.to_mark is not None else "now"
        return f"{start} .. {end}"


@dataclass(frozen=True, kw_only=True)
class StepBase:
    """What every step carries: its place in the plan and its line in the file."""

    index: int        # 0-based position in the plan
    line: int         # line of the step in the plan file
    kind: ClassVar[str] = ""


@dataclass(frozen=True, kw_only=True)
class CommandStep(StepBase):
    """COMMAND to the board; unspecified fields keep their previous value."""

    kind: ClassVar[str] = "command"
    enable: bool | None = None
    speed_ref_rpm: float | None = None
    speed_source: str | None = None
    torque_mode: bool | None = None
    torque_ref_nm: float | None = None
    flux_ref_wb: float | None = None

    def changes(self) -> dict[str, Any]:
        """The fields this step sets (what BenchSession.send_command takes)."""
        names = ("enable", "speed_ref_rpm", "speed_source", "torque_mode", "torque_ref_nm",
                 "flux_ref_wb")
        return {n: getattr(self, n) for n in names if getattr(self, n) is not None}


@dataclass(frozen=True, kw_only=True)
class ParamSetStep(StepBase):
    """PARAM_SET to the board, in order; each value is read back."""

    kind: ClassVar[str] = "param_set"
    params: tuple[tuple[str, float], ...]


@dataclass(frozen=True, kw_only=True)
class LoadStep(StepBase):
    """A load-torque profile applied from this step's time t0 on.

    constant: torque_nm. step: torque_nm after delay_s. ramp: from the load
    at t0 to torque_nm over duration_s. table: linear interpolation of
    (t - t0, torque) points, held after the last (or repeated). speed_proportional:
    offset_nm + nm_per_rad_s * mechanical speed.
    """

    kind: ClassVar[str] = "load"
    type: str
    torque_nm: float | None = None
    delay_s: float = 0.0
    duration_s: float | None = None
    points: tuple[tuple[float, float], ...] = ()
    repeat: bool = False
    nm_per_rad_s: float | None = None
    offset_nm: float = 0.0

    def torque_at(self, t_since_s: float, speed_rad_s: float, previous_nm: float) -> float:
        """Load torque (Nm) t_since_s after the step, at a speed, given the load before it."""
        if self.type == "constant":
            return float(self.torque_nm)
        if self.type == "step":
            return float(self.torque_nm) if t_since_s >= self.delay_s else previous_nm
        if self.type == "ramp":
            frac = min(max(t_since_s / self.duration_s, 0.0), 1.0)
            return previous_nm + frac * (float(self.torque_nm) - previous_nm)
        if self.type == "table":
            ts = [p[0] for p in self.points]
            t = t_since_s
            if self.repeat and ts[-1] > 0:
                t = math.fmod(t, ts[-1])
            if t <= ts[0]:
                return self.points[0][1]
            for (ta, va), (tb, vb) in zip(self.points, self.points[1:]):
                if t <= tb:
                    return va if tb == ta else va + (vb - va) * (t - ta) / (tb - ta)
            return self.points[-1][1]
        return self.offset_nm + float(self.nm_per_rad_s) * speed_rad_s


@dataclass(frozen=True, kw_only=True)
class DcLinkStep(StepBase):
    """DC-link source voltage, reached linearly over ramp_s (0 = a step)."""

    kind: ClassVar[str] = "dc_link"
    voltage_v: float
    ramp_s: float = 0.0


@dataclass(frozen=True, kw_only=True)
class PlantParamStep(StepBase):
    """Changes motor constants of the plant (a hotter winding); the board is not told."""

    kind: ClassVar[str] = "plant_param"
    params: tuple[tuple[str, float], ...]


@dataclass(frozen=True, kw_only=True)
class FaultStep(StepBase):
    """A fault switched on (or lifted, with clear) now; see FAULTS for names and arguments."""

    kind: ClassVar[str] = "fault"
    name: str
    args: Mapping[str, Any] = field(default_factory=dict)
    duration_s: float | None = None
    clear: bool = False


@dataclass(frozen=True, kw_only=True)
class RunStep(StepBase):
    """Advances the session by duration_s of simulated time."""

    kind: ClassVar[str] = "run"
    duration_s: float


@dataclass(frozen=True, kw_only=True)
class WaitUntilStep(StepBase):
    """Run until a condition on a signal has held for hold_s; TIMEOUT after timeout_s."""

    kind: ClassVar[str] = "wait_until"
    signal: str
    comparison: str
    value: float
    unit: str
    timeout_s: float
    tolerance: float | None = None
    hold_s: float = 0.0

    def predicate(self, signal_unit: str) -> Callable[[float], bool]:
        """A fast test of one sample given in signal_unit (thresholds converted once)."""
        q = Quantity(self.value, self.unit).to(signal_unit)
        if self.comparison == "above":
            return lambda v: v > q
        if self.comparison == "below":
            return lambda v: v < q
        if self.comparison == "at_least":
            return lambda v: v >= q
        if self.comparison == "at_most":
            return lambda v: v <= q
        tol = abs(Quantity(self.tolerance, self.unit).to(signal_unit))
        return lambda v: abs(v - q) <= tol

    def describe(self) -> str:
        words = {"above": ">", "below": "<", "at_least": ">=", "at_most": "<="}
        if self.comparison == "within":
            cond = f"{self.signal} within {self.value:g} +- {self.tolerance:g} {self.unit}"
        else:
            cond = f"{self.signal} {words[self.comparison]} {self.value:g} {self.unit}"
        hold = f" for {self.hold_s * 1e3:g} ms" if self.hold_s else ""
        return f"{cond}{hold} (timeout {self.timeout_s:g} s)"


@dataclass(frozen=True, kw_only=True)
class WaitReadyStep(StepBase):
    """Run until the board reports it is ready (STATUS RUNNING after its start-up, SPEC.md 2
    item 5); TIMEOUT after timeout_s naming its state, FAIL at once when it reports FAULT.
    Names the moment it became ready `mark` (a check window anchor)."""

    kind: ClassVar[str] = "wait_ready"
    timeout_s: float
    mark: str = "ready"

    def describe(self) -> str:
        return f"board ready (timeout {self.timeout_s:g} s), mark '{self.mark}'"


@dataclass(frozen=True, kw_only=True)
class MarkStep(StepBase):
    """Names the current simulated time, for check windows."""

    kind: ClassVar[str] = "mark"
    name: str


@dataclass(frozen=True, kw_only=True)
class CheckStep(StepBase):
    """A named check over a window; `roles` maps the kind's signal roles to names (or constants)."""

    kind: ClassVar[str] = "check"
    name: str
    check_kind: str
    roles: Mapping[str, str | Quantity]
    args: Mapping[str, Any]
    window: Window | None
    limits: Limits | None
    source: str
    plot: bool = True
    role: str = "acceptance"            # CHECK_ROLES
    note: str = ""
    # Limits for named profiles where the physics differs (`profile_limits:`); the
    # others use `limits`.
    profile_limits: Mapping[str, Limits] = field(default_factory=lambda: MappingProxyType({}))
    # The formulas behind `limits` (low/high/marginal -> Derivation) and behind each
    # profile's `profile_limits`, as evaluated for the run (hil.plans.plan_formulas).
    derivations: Mapping[str, Derivation] = field(default_factory=lambda: MappingProxyType({}))
    profile_derivations: Mapping[str, Mapping[str, Derivation]] = field(
        default_factory=lambda: MappingProxyType({}))
    # (role, note) of a profile whose `profile_limits` entry gives its own
    profile_roles: Mapping[str, tuple[str, str]] = field(
        default_factory=lambda: MappingProxyType({}))

    @property
    def signals(self) -> tuple[str, ...]:
        return tuple(v for v in self.roles.values() if isinstance(v, str))

    def limits_for(self, profile: str | None) -> Limits | None:
        """The limits that apply on a profile (its label): its own if the plan gives them."""
        if profile is not None and profile in self.profile_limits:
            return self.profile_limits[profile]
        return self.limits

    def role_for(self, profile: str | None) -> tuple[str, str]:
        """(role, note) on a profile: its `profile_limits` entry's when it gives one."""
        if profile is not None and profile in self.profile_roles:
            return self.profile_roles[profile]
        return self.role, self.note

    def derivations_for(self, profile: str | None) -> Mapping[str, Derivation]:
        """The formulas behind limits_for(profile): bound name -> Derivation."""
        if profile is not None and profile in self.profile_limits:
            return self.profile_derivations.get(profile, MappingProxyType({}))
        return self.derivations


Step = Union[CommandStep, ParamSetStep, LoadStep, DcLinkStep, PlantParamStep, FaultStep,
             RunStep, WaitUntilStep, WaitReadyStep, MarkStep, CheckStep]


@dataclass(frozen=True)
class PlotSpec:
    """A figure the report draws: signals against time, or y against x (a locus)."""

    title: str
    type: str                       # "time" | "xy"
    signals: tuple[str, ...]        # time: the signals; xy: (x, y)
    unit: str | None = None         # time plots: convert every signal to this unit
    window: Window | None = None
    line: int | None = None


@dataclass(frozen=True)
class Plan:
    """A validated plan: its steps in order, the profiles it runs on, link, mode and plots."""

    name: str
    description: str
    source_path: Path
    steps: tuple[Step, ...]
    profile: str | None = None          # a profile name, or a path as written
    profile_path: Path | None = None    # resolved when `profile` is a path (relative to the plan)
    overrides: Mapping[str, Any] = field(default_factory=lambda: MappingProxyType({}))
    link: str | None = None
    board_path: Path | None = None      # `board:`, a board file relative to the plan
    mode: str | None = None
    timeout_s: float | None = None      # wall-clock budget for the whole plan
    plots: tuple[PlotSpec, ...] = ()
    profiles: tuple[ProfileRef, ...] = ()   # every profile it runs on (`profile` / `profiles`)
    expect_fault: bool = False          # a board FAULT or shoot-through does not end the plan
    # Formulas (hil.plans.plan_formulas): the document they are re-evaluated from for each
    # run (None: the plan has none), the profile label they were evaluated for, and the
    # plan's constants.
    document: YamlDocument | None = None
    formula_profile: str | None = None
    constants: Mapping[str, Derivation] = field(default_factory=lambda: MappingProxyType({}))

    @property
    def checks(self) -> tuple[CheckStep, ...]:
        return tuple(s for s in self.steps if isinstance(s, CheckStep))

    @property
    def marks(self) -> tuple[str, ...]:
        return tuple(s.name if isinstance(s, MarkStep) else s.mark for s in self.steps
                     if isinstance(s, (MarkStep, WaitReadyStep)))

    def signals_used(self) -> set[str]:
        used: set[str] = set()
        for s in self.steps:
            if isinstance(s, CheckStep):
                used.update(s.signals)
            elif isinstance(s, WaitUntilStep):
                used.add(s.signal)
        for p in self.plots:
            used.update(p.signals)
        return used

    def min_sim_duration_s(self) -> float:
        """Simulated time the plan takes at least (runs, and immediately met waits)."""
        return sum(s.duration_s for s in self.steps if isinstance(s, RunStep))

    def max_sim_duration_s(self) -> float:
        """Simulated time the plan takes at most (every wait_until to its timeout)."""
        return self.min_sim_duration_s() + sum(s.timeout_s for s in self.steps
                                               if isinstance(s, (WaitUntilStep, WaitReadyStep)))


# --------------------------------------------------------------------------- #
# Schemas                                                                      #
# --------------------------------------------------------------------------- #

_QUANTITY = obj({"value": NUMBER, "unit": {"type": "string"}}, ["value", "unit"])
_WINDOW = obj({"from": NAME, "offset_s": NUMBER, "duration_s": POSITIVE, "to": NAME,
                "to_offset_s": NUMBER})
_LIMITS = obj({"low": NUMBER, "high": NUMBER, "marginal": NON_NEGATIVE,
                "comparison": {"enum": ["inside", "outside"]}, "unit": {"type": "string"}},
               ["unit"])

PLAN_SCHEMA = obj({
    "name": NAME,
    "description": {"type": "string"},
    "profile": NAME,
    "profiles": {"type": "array", "minItems": 1, "uniqueItems": True, "items": NAME},
    "overrides": {"type": "object"},
    "link": {"type": "string", "pattern": LINK_PATTERN},
    "board": NAME,
    "mode": {"enum": list(MODES)},
    "timeout_s": POSITIVE,
    "expect_fault": {"type": "boolean"},
    "steps": {"type": "array", "minItems": 1},
    "plots": {"type": "array"},
    "constants": {"type": "object", "additionalProperties": _QUANTITY},
}, ["name", "steps"])

STEP_SCHEMAS: dict[str, dict] = {
    "command": obj({"enable": BOOLEAN, "speed_ref_rpm": NUMBER, "speed_source": {"enum": list(SPEED_SOURCES)},
                     "torque_mode": BOOLEAN, "torque_ref_nm": NUMBER, "flux_ref_wb": POSITIVE}, min_props=1),
    "param_set": {"type": "object", "minProperties": 1, "additionalProperties": NUMBER},
    "load": {"type": "object", "required": ["type"], "properties": {"type": {"enum": list(LOAD_TYPES)}}},
    "dc_link": obj({"voltage_v": POSITIVE, "ramp_s": NON_NEGATIVE}, ["voltage_v"]),
    "plant_param": {"type": "object", "minProperties": 1, "additionalProperties": POSITIVE},
    "fault": {"type": "object", "required": ["name"], "properties": {"name": {"enum": list(FAULTS)}}},
    "run": obj({"duration_s": POSITIVE}, ["duration_s"]),
    "wait_until": obj({"signal": NAME, "comparison": {"enum": list(WAIT_COMPARISONS)},
                        "value": NUMBER, "tolerance": POSITIVE, "unit": {"type": "string"},
                        "timeout_s": POSITIVE, "hold_s": NON_NEGATIVE},
                       ["signal", "comparison", "value", "timeout_s"]),
    "wait_ready": obj({"timeout_s": POSITIVE, "mark": NAME}, ["timeout_s"]),
    "mark": NAME,
    "check": {"type": "object", "required": ["name", "kind"],
              "properties": {"name": NAME, "kind": {"enum": list(CHECK_KINDS)}}},
}

LOAD_SCHEMAS: dict[str, dict] = {
    "constant": obj({"type": {}, "torque_nm": NUMBER}, ["type", "torque_nm"]),
    "step": obj({"type": {}, "torque_nm": NUMBER, "delay_s": NON_NEGATIVE}, ["type", "torque_nm"]),
    "ramp": obj({"type": {}, "torque_nm": NUMBER, "duration_s": POSITIVE}, ["type", "torque_nm", "duration_s"]),
    "table": obj({"type": {}, "points": {"type": "array", "minItems": 1,
                                          "items": {"type": "array", "minItems": 2, "maxItems": 2,
                                                    "items": NUMBER}},
                   "repeat": BOOLEAN}, ["type", "points"]),
    "speed_proportional": obj({"type": {}, "nm_per_rad_s": NUMBER, "offset_nm": NUMBER},
                               ["type", "nm_per_rad_s"]),
}

# A profile's own limits may carry their own role (e.g. regression on one profile only).
_PROFILE_LIMITS = obj({**_LIMITS["properties"], "role": {"enum": list(CHECK_ROLES)},
                       "note": {"type": "string"}}, ["unit"])
_CHECK_COMMON = {"name": NAME, "kind": {}, "window": _WINDOW, "limits": _LIMITS, "plot": BOOLEAN,
                 "role": {"enum": list(CHECK_ROLES)}, "note": {"type": "string"},
                 "profile_limits": {"type": "object", "minProperties": 1,
                                    "additionalProperties": _PROFILE_LIMITS}}
_ARG_SCHEMAS = {"number": NUMBER, "positive": POSITIVE, "nonneg": NON_NEGATIVE, "integer": POSITIVE_INT,
                "bool": BOOLEAN, "quantity": _QUANTITY, "check": NAME}


def _check_schema(kind: CheckKind) -> dict:
    props = dict(_CHECK_COMMON)
    required = ["name", "kind"]
    for role in kind.roles:
        props[role.key] = ({"oneOf": [NAME, _QUANTITY]} if role.allow_quantity else NAME)
        if role.required:
            required.append(role.key)
    for key, spec in kind.args.items():
        props[key] = {"enum": list(spec.choices)} if spec.type == "choice" else _ARG_SCHEMAS[spec.type]
        if spec.required:
            required.append(key)
    return obj(props, required)


CHECK_SCHEMAS: dict[str, dict] = {name: _check_schema(k) for name, k in CHECK_KINDS.items()}

PLOT_SCHEMA = {"type": "object", "required": ["title"], "additionalProperties": False,
               "properties": {"title": NAME, "type": {"enum": ["time", "xy"]},
                              "signals": {"type": "array", "minItems": 1, "items": NAME},
                              "x": NAME, "y": NAME, "unit": {"type": "string"},
                              "window": _WINDOW}}

# --------------------------------------------------------------------------- #
# Loading                                                                      #
# --------------------------------------------------------------------------- #

def load_plan(path: str | Path) -> Plan:
    """Reads and validates a plan file; ConfigError (file, line, key) on any problem."""
    return _build(load_yaml(path), Path(path))


def parse_plan(text: str, source: str = "<string>", base_dir: Path | None = None) -> Plan:
    """Validates a plan given as text (tests, tools); a profile path resolves against base_dir."""
    path = Path(source) if base_dir is None else Path(base_dir) / Path(source).name
    return _build(parse_yaml(text, source), path)


def looks_like_plan(path: str | Path) -> bool:
    """True for a YAML file that is (meant to be) a plan: a mapping with 'steps' or 'name'.

    A file that is not valid YAML counts as a plan, so that its error is shown
    rather than the file silently skipped; bench profiles and other data
    files (no 'steps', no 'name') are not plans.
    """
    try:
        data = load_yaml(path).data
    except ConfigError:
        return True
    return isinstance(data, dict) and ("steps" in data or "name" in data)


def plan_files(paths: Iterable[str | Path]) -> list[Path]:
    """Plan files named or found (recursively, *.yaml and *.yml, sorted) in directories."""
    out: list[Path] = []
    for p in map(Path, paths):
        if p.is_dir():
            out.extend(sorted(f for f in p.rglob("*") if f.suffix in (".yaml", ".yml")
                              and f.is_file() and looks_like_plan(f)))
        else:
            out.append(p)
    return out


def _step_inputs(step: "Step"):
    """(key path below the step, value, check) of every control input a step holds."""
    if isinstance(step, CommandStep):
        for key, value in step.changes().items():
            yield (key,), value, lambda limits, v, key=key: limits.command({key: v})
    elif isinstance(step, LoadStep):
        torque = lambda limits, v: limits.torque_nm(v)   # noqa: E731
        for key in ("torque_nm", "offset_nm"):
            if getattr(step, key) is not None:
                yield (key,), getattr(step, key), torque
        for j, (_, value) in enumerate(step.points):
            yield ("points", j, 1), value, torque
        if step.nm_per_rad_s is not None:
            yield ("nm_per_rad_s",), step.nm_per_rad_s, lambda limits, v: limits.load_damping(v)
    elif isinstance(step, DcLinkStep):
        yield ("voltage_v",), step.voltage_v, lambda limits, v: limits.dc_link_voltage_v(v)


def check_control_inputs(steps: Iterable["Step"], limits: ControlLimits, source: str,
                         line_of: Callable[[KeyPath], int | None] | None = None) -> None:
    """Every command, load and DC-link value of the steps within `limits`
    (hil.control_inputs, the validator of every control input); ConfigError naming
    the file, the line and the key of the first one outside."""
    for step in steps:
        for sub, value, check in _step_inputs(step):
            try:
                check(limits, value)
            except ControlInputError as exc:
                path = ("steps", step.index, step.kind) + sub
                line = line_of(path) if line_of is not None else step.line
                raise ConfigError(f"{value!r} refused: {exc.why}", source, line,
                                  format_key(path)) from None


def bind_plan(plan: Plan, profile, board, profile_label: str | None) -> Plan:
    """The plan with its formulas evaluated for one run (its profile, with the plan's
    overrides applied, and its board file); the plan itself when it has none. ConfigError
    naming the file, line and key of a formula that fails on this profile or board."""
    if plan.document is None:
        return plan
    return _build(plan.document, plan.source_path, context=(profile_label, profile, board))


def _build(doc: YamlDocument, path: Path, context=None) -> Plan:
    """context: (profile label, profile, board) to evaluate the plan's formulas against;
    None: every profile the plan lists, with its board (hil.plans.plan_formulas)."""
    from hil.plans import plan_formulas

    original = doc
    data = doc.data
    if not isinstance(data, dict):
        raise doc.error((), f"a plan is a mapping with at least 'name' and 'steps', got {python_type(data)}")
    derivations: dict = {}
    constants: dict = {}
    formula_profile = None
    if plan_formulas.has_formulas(data):
        contexts = [context] if context is not None else plan_formulas.plan_contexts(doc, path, resolve_profile)
        label, profile, board = contexts[0]
        data, derivations, constants = plan_formulas.substitute(
            doc, plan_formulas.named_values(profile, board, label))
        formula_profile = label
        for other in contexts[1:]:
            _build(original, path, context=other)   # the plan is valid on each profile it lists
        doc = YamlDocument(data, doc.source, doc.lines)
    # jsonschema only for a plan the quick check does not accept (plant_rt.profile)
    v = SchemaChecker(doc, {LINK_PATTERN: "stub, stub-pty, stub-can, qemu, serial:PORT or can:INTERFACE:CHANNEL"})
    v.check(PLAN_SCHEMA, data, ())
    if "profile" in data and "profiles" in data:
        raise doc.error(("profiles",), "give either profile (one) or profiles (a list), not both")
    refs: list[ProfileRef] = []
    if "profiles" in data:
        for i, value in enumerate(data["profiles"]):
            try:
                refs.append(resolve_profile(value, path.parent))
            except ValueError as exc:
                raise doc.error(("profiles", i), str(exc)) from None
    elif data.get("profile") is not None:
        try:
            refs.append(resolve_profile(data["profile"], path.parent))
        except ValueError as exc:
            raise doc.error(("profile",), str(exc)) from None
    else:
        refs.append(ProfileRef("paper", None))
    profile = data.get("profile", data["profiles"][0] if "profiles" in data else None)
    profile_path = refs[0].path
    board_path = None
    if data.get("board") is not None:
        board_path = (path.parent / data["board"]).resolve()
        if not board_path.is_file():
            raise doc.error(("board",), f"board file not found: {board_path}")
    state = _BuildState(doc, v, str(doc.source), tuple(r.label for r in refs), derivations)
    steps = tuple(state.step(raw, i) for i, raw in enumerate(data["steps"]))
    # finite and float32 now; the profile's ranges when a run has chosen its profile
    check_control_inputs(steps, UNBOUNDED, str(doc.source), doc.line_of)
    plots = tuple(state.plot(raw, i) for i, raw in enumerate(data.get("plots", [])))
    return Plan(
        name=data["name"], description=data.get("description", "").strip(),
        source_path=path, steps=steps, profile=profile, profile_path=profile_path,
        overrides=MappingProxyType(dict(data.get("overrides", {}))),
        link=data.get("link"), board_path=board_path, mode=data.get("mode"),
        timeout_s=None if data.get("timeout_s") is None else float(data["timeout_s"]),
        plots=plots, profiles=tuple(refs), expect_fault=bool(data.get("expect_fault", False)),
        document=original if formula_profile is not None else None,
        formula_profile=formula_profile, constants=MappingProxyType(constants),
    )


class _BuildState:
    """Walks the steps in order, so marks and checks are known before they are used."""

    def __init__(self, doc: YamlDocument, v: SchemaChecker, source: str,
                 profiles: tuple[str, ...] = (), derivations: Mapping | None = None):
        self.doc, self.v, self.source = doc, v, source
        self.derivations = derivations or {}
        self.profiles = profiles
        self.marks: dict[str, int] = {}             # name -> line
        self.checks: dict[str, tuple[int, str | None]] = {}  # name -> (line, measured unit)

    def err(self, path: KeyPath, message: str) -> ConfigError:
        return self.doc.error(path, message)

    def line(self, path: KeyPath) -> int:
        return self.doc.line_of(path) or 0

    # ------------------------------------------------------------------ steps
    def step(self, raw: Any, i: int) -> Step:
        path: KeyPath = ("steps", i)
        if not isinstance(raw, dict) or len(raw) != 1:
            got = (f"a mapping with {len(raw)} keys ({', '.join(map(str, raw))})"
                   if isinstance(raw, dict) else python_type(raw))
            raise self.err(path, f"a step is a mapping with exactly one key, the step kind "
                                 f"({', '.join(STEP_SCHEMAS)}); got {got}")
        kind, body = next(iter(raw.items()))
        if kind not in STEP_SCHEMAS:
            raise self.err(path + (kind,), f"unknown step kind '{kind}'; expected one of: "
                                           f"{', '.join(STEP_SCHEMAS)}")
        bpath = path + (kind,)
        self.v.check(STEP_SCHEMAS[kind], body, bpath)
        common = {"index": i, "line": self.line(bpath)}
        return getattr(self, f"_{kind}")(body, bpath, common)

    def _command(self, body: dict, path: KeyPath, common: dict) -> CommandStep:
        return CommandStep(**common, **{k: (float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) else v)
                                        for k, v in body.items()})

    def _param_set(self, body: dict, path: KeyPath, common: dict) -> ParamSetStep:
        for name in body:
            if name in READ_ONLY_BOARD_PARAMS:
                raise self.err(path + (name,), f"board parameter '{name}' is read-only")
            if not _PARAM_NAME.match(str(name)):
                raise self.err(path + (name,), f"'{name}' is not a parameter name "
                                               f"(lower_snake_case, as SPEC 8 and board files "
                                               f"write them)")
        return ParamSetStep(**common, params=tuple((k, float(x)) for k, x in body.items()))

    def _load(self, body: dict, path: KeyPath, common: dict) -> LoadStep:
        self.v.check(LOAD_SCHEMAS[body["type"]], body, path)
        points = tuple((float(t), float(x)) for t, x in body.get("points", []))
        for j in range(1, len(points)):
            if points[j][0] < points[j - 1][0]:
                raise self.err(path + ("points", j), "table times must not decrease")
        if points and points[0][0] < 0:
            raise self.err(path + ("points", 0), "table times start at 0 or later")
        fields = {k: (float(x) if isinstance(x, (int, float)) and not isinstance(x, bool) else x)
                  for k, x in body.items() if k != "points"}
        return LoadStep(**common, **fields, points=points)

    def _dc_link(self, body: dict, path: KeyPath, common: dict) -> DcLinkStep:
        return DcLinkStep(**common, voltage_v=float(body["voltage_v"]),
                          ramp_s=float(body.get("ramp_s", 0.0)))

    def _plant_param(self, body: dict, path: KeyPath, common: dict) -> PlantParamStep:
        for name in body:
            if name not in PLANT_PARAMS:
                raise self.err(path + (name,), f"unknown plant parameter '{name}'; known: "
                                               f"{', '.join(PLANT_PARAMS)}")
        return PlantParamStep(**common, params=tuple((k, float(x)) for k, x in body.items()))

    def _fault(self, body: dict, path: KeyPath, common: dict) -> FaultStep:
        name = body["name"]
        rest = {k: x for k, x in body.items() if k != "name"}
        schema = FAULTS[name]
        if rest.get("clear"):
            # Lifting a fault needs no arguments beyond its name.
            extra = [k for k in rest if k != "clear"]
            if extra:
                raise self.err(path + (extra[0],), f"'clear: true' lifts fault '{name}' and takes "
                                                   f"no other key")
        else:
            self.v.check(schema, rest, path)
        return FaultStep(**common, name=name,
                         args=MappingProxyType({k: x for k, x in rest.items()
                                                if k not in ("duration_s", "clear")}),
                         duration_s=None if "duration_s" not in rest else float(rest["duration_s"]),
                         clear=bool(rest.get("clear", False)))

    def _run(self, body: dict, path: KeyPath, common: dict) -> RunStep:
        return RunStep(**common, duration_s=float(body["duration_s"]))

    def _wait_until(self, body: dict, path: KeyPath, common: dict) -> WaitUntilStep:
        sig_unit = self.known_signal(body["signal"], path + ("signal",))
        unit = self.unit_compatible(body.get("unit", sig_unit), sig_unit, path + ("unit",),
                                    f"signal '{body['signal']}'")
        if body["comparison"] == "within" and "tolerance" not in body:
            raise self.err(path, "comparison 'within' needs a tolerance (in the same unit as value)")
        if body["comparison"] != "within" and "tolerance" in body:
            raise self.err(path + ("tolerance",), f"tolerance only applies to comparison 'within', "
                                                  f"not '{body['comparison']}'")
        if body.get("hold_s", 0.0) >= body["timeout_s"]:
            raise self.err(path + ("hold_s",), "hold_s must be shorter than timeout_s")
        return WaitUntilStep(**common, signal=body["signal"], comparison=body["comparison"],
                             value=float(body["value"]), unit=unit,
                             timeout_s=float(body["timeout_s"]),
                             tolerance=None if "tolerance" not in body else float(body["tolerance"]),
                             hold_s=float(body.get("hold_s", 0.0)))

    def _wait_ready(self, body: dict, path: KeyPath, common: dict) -> WaitReadyStep:
        mark = body.get("mark", "ready")
        where = path + ("mark",) if "mark" in body else path
        self.new_mark(mark, where, common["line"],
                      "" if "mark" in body else "; a second wait_ready needs its own 'mark: NAME'")
        return WaitReadyStep(**common, timeout_s=float(body["timeout_s"]), mark=mark)

    def _mark(self, body: str, path: KeyPath, common: dict) -> MarkStep:
        self.new_mark(body, path, common["line"])
        return MarkStep(**common, name=body)

    def new_mark(self, name: str, path: KeyPath, line: int, hint: str = "") -> None:
        if name in RESERVED_MARKS:
            raise self.err(path, f"'{name}' is a reserved mark name ({', '.join(RESERVED_MARKS)})")
        if name in self.marks:
            raise self.err(path, f"mark '{name}' is already set at line {self.marks[name]}{hint}")
        self.marks[name] = line

    def _check(self, body: dict, path: KeyPath, common: dict) -> CheckStep:
        kind = CHECK_KINDS[body["kind"]]
        self.v.check(CHECK_SCHEMAS[kind.name], body, path)
        name = body["name"]
        if name in self.checks:
            raise self.err(path + ("name",), f"check name '{name}' is already used at line "
                                             f"{self.checks[name][0]}; names label report rows")
        roles: dict[str, str | Quantity] = {}
        role_units: dict[str, str] = {}
        for role in kind.roles:
            if role.key not in body:
                continue
            raw = body[role.key]
            rpath = path + (role.key,)
            if isinstance(raw, dict):
                roles[role.key] = self.quantity(raw, rpath)
                role_units[role.key] = roles[role.key].unit
            else:
                role_units[role.key] = self.known_signal(raw, rpath)
                roles[role.key] = raw
        main_unit = role_units.get("signal") or role_units.get("alpha")
        for key, unit_ in role_units.items():
            if main_unit is not None and not compatible(unit_, main_unit):
                raise self.err(path + (key,), f"'{key}' is in {unit_}, which does not compare with "
                                              f"the signal's {main_unit}")
        args: dict[str, Any] = {}
        for key, spec in kind.args.items():
            apath = path + (key,)
            if key in body:
                args[key] = self.arg(spec, body[key], apath, main_unit)
            else:
                args[key] = spec.default
        self.kind_rules(kind, body, args, path)
        window = self.window(body.get("window"), path + ("window",), for_check=True)
        measured_unit = result_unit(kind, role_units)
        if kind.name == "compare":
            measured_unit = "1" if args["operation"] == "ratio" else self.checks[args["a"]][1]
        role = body.get("role", "acceptance")
        note = str(body.get("note", "")).strip()
        if role == "regression" and not note:
            raise self.err(path + ("role",), "a regression check needs a 'note': the measurement "
                                             "its bound came from and why it is not derived")
        if kind.limits_required and role != "finding" and "limits" not in body:
            raise self.err(path, f"'{kind.name}' needs 'limits' (only a role: finding check "
                                 f"may leave them out)")
        limits = None
        if "limits" in body:
            limits = self.limits(body["limits"], path + ("limits",), measured_unit, kind)
        per_profile: dict[str, Limits] = {}
        profile_roles: dict[str, tuple[str, str]] = {}
        for label, raw in body.get("profile_limits", {}).items():
            lpath = path + ("profile_limits", label)
            if label not in self.profiles:
                raise self.err(lpath, f"profile '{label}' is not one this plan runs on "
                                      f"({', '.join(self.profiles)})")
            per_profile[label] = self.limits(raw, lpath, measured_unit, kind)
            if "role" in raw or "note" in raw:
                own_role = raw.get("role", role)
                own_note = str(raw.get("note", "")).strip()
                if own_role == "regression" and not own_note:
                    raise self.err(lpath + ("role",), "a regression bound needs a 'note': the "
                                                      "measurement it came from")
                profile_roles[label] = (own_role, own_note)
        if per_profile and limits is None:
            raise self.err(path + ("profile_limits",), "profile_limits refine 'limits': give "
                                                       "'limits' for the other profiles too")
        self.checks[name] = (common["line"], limits.unit if limits is not None else measured_unit)

        def formulas(lpath: KeyPath) -> Mapping[str, Derivation]:
            return MappingProxyType({k: self.derivations[lpath + (k,)]
                                     for k in ("low", "high", "marginal")
                                     if lpath + (k,) in self.derivations})
        derived = formulas(path + ("limits",))
        per_profile_derived = {label: formulas(path + ("profile_limits", label))
                               for label in per_profile}
        return CheckStep(**common, name=name, check_kind=kind.name,
                         roles=MappingProxyType(roles), args=MappingProxyType(args),
                         window=window, limits=limits, source=self.source,
                         plot=bool(body.get("plot", True)), role=role, note=note,
                         profile_limits=MappingProxyType(per_profile), derivations=derived,
                         profile_derivations=MappingProxyType(per_profile_derived),
                         profile_roles=MappingProxyType(profile_roles))

    def kind_rules(self, kind: CheckKind, body: dict, args: dict, path: KeyPath) -> None:
        if kind.name == "settling_time" and "band" in body and "band_pct" in body:
            raise self.err(path + ("band",), "give either band (absolute) or band_pct, not both")
        if kind.name == "settling_time" and "band" in body:
            args["band_pct"] = None
        if kind.name == "rise_time" and not args["from_pct"] < args["to_pct"] <= 100:
            raise self.err(path + ("to_pct",), "need 0 <= from_pct < to_pct <= 100")
        if kind.name == "thd" and args["harmonics"] < 2:
            raise self.err(path + ("harmonics",), "harmonics counts up from 2 (the first harmonic "
                                                  "is the fundamental)")
        if kind.name == "compare":
            for key in ("a", "b"):
                ref = args[key]
                if ref not in self.checks:
                    known = ", ".join(self.checks) or "none yet"
                    raise self.err(path + (key,), f"check '{ref}' is not defined before this one "
                                                  f"(earlier checks: {known})")

    # ---------------------------------------------------------------- pieces
    def known_signal(self, name: str, path: KeyPath) -> str:
        if name in SENSOR_SET_SIGNALS:      # the board's set decides (runner.check_plan_board)
            return SENSOR_SET_SIGNALS[name]
        if name not in SIGNAL_CATALOG:
            import difflib      # an unknown signal's message only; not worth importing per plan

            close = difflib.get_close_matches(name, list(SIGNAL_CATALOG), n=1, cutoff=0.75)
            group = name.split(".", 1)[0]
            same = sorted(s for s in SIGNAL_CATALOG if s.startswith(group + "."))
            if close:
                hint = f"; did you mean '{close[0]}'?"
            elif same:
                hint = f"; signals of '{group}': {', '.join(same)}"
            else:
                hint = "; signal names start with plant., sensor., ctrl., cmd. or board."
            raise self.err(path, f"unknown signal '{name}'{hint}")
        return SIGNAL_CATALOG[name]

    def unit_compatible(self, unit_: str, expected: str | None, path: KeyPath, what: str) -> str:
        try:
            u = canonical(unit_)
        except UnitError as exc:
            raise self.err(path, str(exc)) from None
        if expected is not None and not compatible(u, expected):
            raise self.err(path, f"unit {u} does not fit {what} (in {expected}; "
                                 f"{lookup_unit(expected).dimension.replace('_', ' ')})")
        return u

    def quantity(self, raw: dict, path: KeyPath, expected: str | None = None,
                 what: str = "") -> Quantity:
        u = self.unit_compatible(raw["unit"], expected, path + ("unit",), what)
        return Quantity(float(raw["value"]), u)

    def arg(self, spec: ArgSpec, raw: Any, path: KeyPath, main_unit: str | None) -> Any:
        if spec.type == "quantity":
            return self.quantity(raw, path, main_unit, "the signal")
        if spec.type in ("number", "positive", "nonneg"):
            return float(raw)
        return raw

    def window(self, raw: dict | None, path: KeyPath, for_check: bool) -> Window | None:
        if raw is None:
            return None
        if "duration_s" in raw and "to" in raw:
            raise self.err(path + ("to",), "give either duration_s or to, not both")
        if "to_offset_s" in raw and "to" not in raw:
            raise self.err(path + ("to_offset_s",), "to_offset_s needs 'to'")
        for key in ("from", "to"):
            mark = raw.get(key)
            if mark is None or mark in RESERVED_MARKS:
                continue
            if for_check and mark not in self.marks:
                known = ", ".join(list(RESERVED_MARKS) + list(self.marks))
                raise self.err(path + (key,), f"mark '{mark}' is not set before this step "
                                              f"(marks so far: {known})")
        return Window(from_mark=raw.get("from", "start"), offset_s=float(raw.get("offset_s", 0.0)),
                      duration_s=None if "duration_s" not in raw else float(raw["duration_s"]),
                      to_mark=raw.get("to"), to_offset_s=float(raw.get("to_offset_s", 0.0)))

    def limits(self, raw: dict, path: KeyPath, measured_unit: str | None, kind: CheckKind) -> Limits:
        u = self.unit_compatible(raw["unit"], measured_unit, path + ("unit",),
                                 f"what {kind.name} measures")
        try:
            return Limits(unit=u, low=_opt_float(raw.get("low")), high=_opt_float(raw.get("high")),
                          marginal=_opt_float(raw.get("marginal")),
                          comparison=raw.get("comparison", "inside"))
        except ValueError as exc:
            raise self.err(path, str(exc)) from None

    def plot(self, raw: Any, i: int) -> PlotSpec:
        path: KeyPath = ("plots", i)
        self.v.check(PLOT_SCHEMA, raw, path)
        ptype = raw.get("type", "time")
        if ptype == "xy":
            for key in ("x", "y"):
                if key not in raw:
                    raise self.err(path, f"an xy plot needs '{key}'")
            if "signals" in raw:
                raise self.err(path + ("signals",), "an xy plot takes x and y, not signals")
            names = (raw["x"], raw["y"])
            keys = ("x", "y")
        else:
            if "signals" not in raw:
                raise self.err(path, "a time plot needs 'signals'")
            for key in ("x", "y"):
                if key in raw:
                    raise self.err(path + (key,), f"'{key}' belongs to type: xy plots")
            names = tuple(raw["signals"])
            keys = tuple(("signals", j) for j in range(len(names)))
        units = []
        for name, key in zip(names, keys):
            units.append(self.known_signal(name, path + (key if isinstance(key, tuple) else (key,))))
        unit_ = None
        if "unit" in raw:
            unit_ = self.unit_compatible(raw["unit"], None, path + ("unit",), "")
            for name, u in zip(names, units):
                if not compatible(u, unit_):
                    raise self.err(path + ("unit",), f"signal '{name}' is in {u}, not convertible to {unit_}")
        window = self.window(raw.get("window"), path + ("window",), for_check=False)
        if window is not None:
            for key, mark in (("from", window.from_mark), ("to", window.to_mark)):
                if mark is not None and mark not in RESERVED_MARKS and mark not in self.marks:
                    raise self.err(path + ("window", key), f"mark '{mark}' is never set in this plan")
        return PlotSpec(title=raw["title"], type=ptype, signals=names, unit=unit_, window=window,
                        line=self.line(path))


def _opt_float(x: Any) -> float | None:
    return None if x is None else float(x)


__all__ = ["Plan", "Step", "StepBase", "CommandStep", "ParamSetStep", "LoadStep", "DcLinkStep",
           "PlantParamStep", "FaultStep", "RunStep", "WaitUntilStep", "WaitReadyStep", "MarkStep", "CheckStep",
           "Window", "PlotSpec", "ProfileRef", "CHECK_ROLES", "resolve_profile", "named_profile_path",
           "named_profile_names", "load_plan", "parse_plan", "bind_plan", "plan_files", "looks_like_plan", "BOARD_PARAMS",
           "PLANT_PARAMS", "FAULTS", "PROFILE_NAMES", "SPEED_SOURCES", "MODES", "WAIT_COMPARISONS", "LOAD_TYPES",
           "STATISTICS", "ConfigError"]
