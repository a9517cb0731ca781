"""Bench profiles: the YAML file that says which motor, inverter, DC link, load, sensors and
control period the bench emulates, validated with the file, line and key of every bad value.

    profile = load_profile()                              # plant_rt/profiles/paper.yaml
    profile = load_profile("my_bench.yaml", overrides={"motor": {"resistance_ohm": 0.6}})

Every section and key is optional; a missing one takes the paper's value (the dataclass
defaults). Unknown keys, wrong types and out-of-range values are errors. Overrides are merged
over the file's values and validated the same way; their errors name the key and say it came
from the overrides.
"""
from __future__ import annotations

import copy
import re
import dataclasses
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

from configfile.schema import SchemaChecker, dataclass_schema, nullable, obj
from configfile.source import ConfigError, YamlDocument, format_key, load_yaml

from plant_rt.dc_link import DcLinkParams
from plant_rt.inverter import InverterParams
from plant_rt.load import LoadParams
from plant_rt.motor import MotorParams
from plant_rt.sensors import SensorParams
from configfile.fields import coerce, param, to_float, type_hints



@dataclass(frozen=True)
class ControllerNames:
    """Which names the profile's `controller` section may hold. The plant does not know the
    board's parameters (they belong to the protocol); the bench passes its list
    (hil.session.board_params.CONTROLLER_NAMES), anyone else gets any lower-case name."""

    settable: tuple[str, ...] | None = None   # None: any lower_snake_case name
    read_only: tuple[str, ...] = ()


@dataclass(frozen=True)
class TimingParams:
    """The controller samples at t_k = k T; its answer takes effect computation_delay_s later."""

    control_period_s: float = param(50.0e-6, gt=0)
    computation_delay_s: float = param(0.0, ge=0)
    max_step_s: float = param(50.0e-6, gt=0)   # longest RK4 step within a switching interval


@dataclass(frozen=True)
class InitialState:
    """The plant's state at t = 0."""

    speed_rad_s: float = param(0.0)     # mechanical
    theta_m_rad: float = param(0.0)     # currents start at zero


@dataclass(frozen=True)
class BenchProfile:
    """A bench profile: every section of the YAML file, defaults filled in."""

    timing: TimingParams = field(default_factory=TimingParams)
    motor: MotorParams = field(default_factory=MotorParams)
    inverter: InverterParams = field(default_factory=InverterParams)
    dc_link: DcLinkParams = field(default_factory=DcLinkParams)
    load: LoadParams = field(default_factory=LoadParams)
    sensors: SensorParams = field(default_factory=SensorParams)
    initial: InitialState = field(default_factory=InitialState)
    controller: dict[str, float] = field(default_factory=dict)
    # How the bench talks to the board (waits, resends, watchdog: protocol/SPEC.md 2.8). Not
    # physics: plant_rt keeps it as data, the bench checks it (session_schema) and uses it.
    session: dict[str, Any] = field(default_factory=dict)
    source: str = "<defaults>"

    @property
    def control_period_s(self) -> float:
        return self.timing.control_period_s

    def as_dict(self) -> dict[str, Any]:
        """Plain nested data (for logs and reports), every section including defaults."""
        out = {}
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            out[f.name] = _plain(dataclasses.asdict(value) if dataclasses.is_dataclass(value)
                                 else value)
        return out


_SNAKE = re.compile(r"^[a-z][a-z0-9_]*$")

SECTIONS = {f.name for f in dataclasses.fields(BenchProfile)} - {"source"}


def profile_schema() -> dict:
    """The profile's structure as JSON Schema (configfile.schema): every section a parameter
    dataclass, `controller` a mapping whose names the bench checks."""
    hints = type_hints(BenchProfile)
    sections = {name: nullable(dataclass_schema(hints[name]))
                for name in SECTIONS if name not in ("controller", "session")}
    sections["controller"] = {"type": ["object", "null"]}
    sections["session"] = {"type": ["object", "null"]}
    return obj(sections)


def default_profile_path() -> Path:
    return Path(__file__).resolve().parent / "profiles" / "paper.yaml"


def load_profile(path: str | Path | None = None,
                 overrides: dict[str, Any] | None = None,
                 controller_names: ControllerNames = ControllerNames(),
                 session_schema: dict | None = None) -> BenchProfile:
    """Reads and validates a bench profile; raises configfile.ConfigError on a bad value.

    `controller_names` and `session_schema` are the bench's: which board parameters the
    `controller` section may name, and the JSON Schema of the `session` section (without
    it, `session` must be a mapping)."""
    path = Path(path) if path is not None else default_profile_path()
    doc = load_yaml(path)
    data = doc.data if doc.data is not None else {}
    marks: set[tuple] = set()
    if overrides:
        if not isinstance(overrides, dict):
            raise ConfigError("overrides must be a mapping of sections",
                              f"{doc.source} (overrides)")
        if not isinstance(data, dict):
            raise doc.error((), "a bench profile is a mapping of sections")
        data = copy.deepcopy(data)
        _merge(data, overrides, (), marks)
    err = _error_factory(doc, marks)
    if isinstance(data, dict):
        schema = profile_schema()
        if session_schema is not None:
            schema["properties"]["session"] = nullable(session_schema)
        QuickSchemaChecker(doc, error=err).check(schema, data)
    return build_profile(data, _error_factory(doc, marks), doc.source, controller_names)


# --------------------------------------------------------------------------- quick acceptance
# jsonschema's import (referencing, attrs, its format checkers, the meta-schemas) is about a
# sixth of a short `hil run`, and it runs on every profile and plan although nearly every
# document is valid. The walker below decides "valid" for the keywords and values these
# schemas use, with jsonschema's semantics; anything else (an invalid document, a keyword or a
# value it does not model) goes to jsonschema, which alone words the errors. So a valid
# document loads without jsonschema and an invalid one fails exactly as before
# (tests/test_quick_schema.py holds the walker to jsonschema on every schema of plans and
# profiles).

class _Undecided(Exception):
    """A keyword or a value the quick check does not model."""


_PLAIN = frozenset({dict, list, str, int, float, bool, type(None)})
_ANNOTATIONS = frozenset({"title", "description", "default", "examples", "$comment",
                          "deprecated", "readOnly", "writeOnly"})


def _is_number(v: Any) -> bool:
    return type(v) is int or type(v) is float      # a bool is not a number


_TYPE_TESTS: dict[str, Callable[[Any], bool]] = {
    "object": lambda v: type(v) is dict,
    "array": lambda v: type(v) is list,
    "string": lambda v: type(v) is str,
    "boolean": lambda v: type(v) is bool,
    "null": lambda v: v is None,
    "number": _is_number,
    # Draft 2020-12: an integer is any number with a zero fractional part (1.0 is one)
    "integer": lambda v: type(v) is int or (type(v) is float and v.is_integer()),
}


def _type(arg: Any, v: Any, schema: dict) -> bool:
    tests = [_TYPE_TESTS.get(t) for t in ([arg] if isinstance(arg, str) else arg)]
    if None in tests:
        raise _Undecided
    return any(test(v) for test in tests)


def _properties(arg: dict, v: Any, schema: dict) -> bool:
    return type(v) is not dict or all(_accepts(sub, v[k]) for k, sub in arg.items() if k in v)


def _additional(arg: Any, v: Any, schema: dict) -> bool:
    if type(v) is not dict or arg is True:
        return True
    props = schema.get("properties", {})
    extras = [k for k in v if k not in props]
    if arg is False:
        return not extras
    return all(_accepts(arg, v[k]) for k in extras)


def _scalar_equal(a: Any, b: Any) -> bool:
    """jsonschema's _utils.equal on scalars: True and 1 (False and 0) differ."""
    if type(a) not in _SCALARS or type(b) not in _SCALARS:
        raise _Undecided
    if a is b:
        return True
    if isinstance(a, str) or isinstance(b, str):
        return a == b
    if type(a) is bool or type(b) is bool:
        return False
    return a == b


_SCALARS = frozenset({str, int, float, bool, type(None)})


def _unique(arg: Any, v: Any, schema: dict) -> bool:
    if not arg or type(v) is not list:
        return True
    if not all(type(x) is str for x in v):
        raise _Undecided
    return len(set(v)) == len(v)


def _items(arg: Any, v: Any, schema: dict) -> bool:
    if type(v) is not list:
        return True
    if "prefixItems" in schema:
        raise _Undecided
    if arg is False:
        return not v
    return all(_accepts(arg, x) for x in v)


def _pattern(arg: str, v: Any, schema: dict) -> bool:
    return type(v) is not str or re.search(arg, v) is not None


def _one_of(arg: list, v: Any, schema: dict) -> bool:
    return [_accepts(sub, v) for sub in arg].count(True) == 1


_KEYWORDS: dict[str, Callable[[Any, Any, dict], bool]] = {
    "type": _type,
    "properties": _properties,
    "additionalProperties": _additional,
    "required": lambda arg, v, s: type(v) is not dict or all(k in v for k in arg),
    "enum": lambda arg, v, s: any(_scalar_equal(e, v) for e in arg),
    "minimum": lambda arg, v, s: not _is_number(v) or not v < arg,
    "maximum": lambda arg, v, s: not _is_number(v) or not v > arg,
    "exclusiveMinimum": lambda arg, v, s: not _is_number(v) or not v <= arg,
    "exclusiveMaximum": lambda arg, v, s: not _is_number(v) or not v >= arg,
    "minLength": lambda arg, v, s: type(v) is not str or not len(v) < arg,
    "maxLength": lambda arg, v, s: type(v) is not str or not len(v) > arg,
    "minItems": lambda arg, v, s: type(v) is not list or not len(v) < arg,
    "maxItems": lambda arg, v, s: type(v) is not list or not len(v) > arg,
    "minProperties": lambda arg, v, s: type(v) is not dict or not len(v) < arg,
    "maxProperties": lambda arg, v, s: type(v) is not dict or not len(v) > arg,
    "items": _items,
    "uniqueItems": _unique,
    "pattern": _pattern,
    "oneOf": _one_of,
    "anyOf": lambda arg, v, s: [_accepts(sub, v) for sub in arg].count(True) > 0,
    "allOf": lambda arg, v, s: [_accepts(sub, v) for sub in arg].count(False) == 0,
    "not": lambda arg, v, s: not _accepts(arg, v),
}


_KNOWN = frozenset(_KEYWORDS) | _ANNOTATIONS


def _accepts(schema: Any, v: Any) -> bool:
    if schema is True or schema is False:
        return schema
    if type(schema) is not dict or type(v) not in _PLAIN:
        raise _Undecided
    # Every keyword known before any is evaluated: a False is then as certain as a True (a
    # keyword modelled here never depends on one that is not, e.g. additionalProperties on
    # patternProperties), which `not` and `oneOf` need.
    if not schema.keys() <= _KNOWN:
        raise _Undecided
    for key, arg in schema.items():
        test = _KEYWORDS.get(key)
        if test is not None and not test(arg, v, schema):
            return False
    return True


def schema_accepts(schema: Any, value: Any) -> bool:
    """True when `value` is certainly valid under the JSON Schema (Draft 2020-12) `schema`, as
    jsonschema's Draft202012Validator would find it; False when it is not, or when the
    schema or the value holds something this check does not model (then only jsonschema
    can tell)."""
    try:
        return _accepts(schema, value)
    except _Undecided:
        return False


class QuickSchemaChecker(SchemaChecker):
    """configfile.schema.SchemaChecker that imports jsonschema only for a document that
    schema_accepts does not accept: the same errors, worded by the same code."""

    def check(self, schema: dict, value: Any, path=()) -> None:
        if not schema_accepts(schema, value):
            super().check(schema, value, path)


def build_profile(data: Any, err: Callable[[tuple, str], ConfigError],
                  source: str = "<data>",
                  controller_names: ControllerNames = ControllerNames()) -> BenchProfile:
    """Validates already-parsed profile data; `err(key_path, message)` makes the errors."""
    if not isinstance(data, dict):
        raise err((), "a bench profile is a mapping of sections "
                      f"({', '.join(sorted(SECTIONS))})")
    hints = type_hints(BenchProfile)
    sections: dict[str, Any] = {}
    for key, value in data.items():
        if key not in SECTIONS:
            raise err((key,), f"unknown section (known: {', '.join(sorted(SECTIONS))})")
        if key == "controller":
            sections[key] = _controller(value, err, controller_names)
        elif key == "session":
            if value is not None and not isinstance(value, dict):
                raise err((key,), "expected a mapping of session settings")
            sections[key] = dict(value or {})
        else:
            sections[key] = _build(hints[key], value, (key,), err)
    profile = BenchProfile(**sections, source=source)
    _cross_check(profile, err)
    return profile


def _build(cls: type, data: Any, path: tuple, err: Callable[[tuple, str], ConfigError]) -> Any:
    names = [f.name for f in dataclasses.fields(cls)]
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise err(path, f"expected a mapping with keys {', '.join(names)}")
    hints = type_hints(cls)
    kwargs = {}
    for key, value in data.items():
        if key not in names:
            raise err(path + (key,), f"unknown key (known: {', '.join(names)})")
        if dataclasses.is_dataclass(hints[key]):
            kwargs[key] = _build(hints[key], value, path + (key,), err)
            continue
        try:
            kwargs[key] = coerce(cls, key, value)
        except ValueError as exc:
            raise err(path + (key,), str(exc)) from None
    return cls(**kwargs)


def _controller(data: Any, err: Callable[[tuple, str], ConfigError],
                names: ControllerNames) -> dict[str, float]:
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise err(("controller",), "expected a mapping of controller parameter names to numbers")
    out = {}
    for key, value in data.items():
        path = ("controller", key)
        if key in names.read_only:
            raise err(path, "read-only controller parameter: the board reports it, the bench "
                            "cannot set it")
        if names.settable is not None and key not in names.settable:
            raise err(path, f"unknown controller parameter (known: {', '.join(names.settable)})")
        if names.settable is None and not (isinstance(key, str) and _SNAKE.match(key)):
            raise err(path, "a controller parameter name is lower_snake_case")
        try:
            out[key] = to_float(value)
        except ValueError as exc:
            raise err(path, str(exc)) from None
    return out


def _cross_check(profile: BenchProfile, err: Callable[[tuple, str], ConfigError]) -> None:
    period = profile.timing.control_period_s
    if profile.timing.computation_delay_s > period:
        raise err(("timing", "computation_delay_s"),
                  f"must be between 0 and one control period ({period:g} s), "
                  f"got {profile.timing.computation_delay_s:g}")
    if profile.inverter.dead_time_s >= 0.5 * period:
        raise err(("inverter", "dead_time_s"),
                  f"must be shorter than half a control period ({0.5 * period:g} s), "
                  f"got {profile.inverter.dead_time_s:g}")
    for key, message in profile.dc_link.problems():
        raise err(("dc_link", key), message)


def _merge(base: dict, over: dict, path: tuple, marks: set[tuple]) -> None:
    for key, value in over.items():
        if isinstance(value, dict) and isinstance(base.get(key), dict):
            _merge(base[key], value, path + (key,), marks)
        else:
            base[key] = copy.deepcopy(value)
            marks.add(path + (key,))


def _error_factory(doc: YamlDocument, marks: set[tuple]) -> Callable[[tuple, str], ConfigError]:
    def err(path: tuple, message: str) -> ConfigError:
        if any(path[:i] in marks for i in range(1, len(path) + 1)):
            return ConfigError(message, f"{doc.source} (overrides)", None, format_key(path) or None)
        return doc.error(path, message)
    return err


def _plain(value: Any) -> Any:
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    return value
