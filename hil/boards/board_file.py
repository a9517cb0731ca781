"""Board files: what a controller board is, apart from what the bench emulates.

A bench profile (plant_rt) says which motor, inverter, DC link and sensors the bench plays. A
board file says what the board under test takes: SPEC's standard parameters it knows besides
the required ones, its own (vendor) parameters with id, unit, range and default, the settings
the bench pushes to it at every session start (its tuning for the motor), and the HELLO
capabilities it must advertise. The same plans then run on any board: a plan's ``param_set``
names are checked against the board file before anything runs.

    name: my ESC rev B
    capabilities: [DUTY, TELEMETRY]
    sensors: [current_a, current_b, vdc, hall]         # SAMPLE_SENSORS' set (SPEC 6.13)
    parameters:
      standard: [torque_limit_nm, overcurrent_a]        # SPEC 8, ids 1-59
      vendor:                                           # ids 60-65535, the board's own
        velocity_lpf_hz: {id: 300, unit: Hz, min: 1, max: 5000, default: 100}
    settings:                                           # pushed after SPEC's required ones
      torque_limit_nm: 0.8
      velocity_lpf_hz: {value: 250, optional: true}     # UNKNOWN answer: logged, run goes on
    profile_settings:                                   # more, on one bench profile only
      paper-hardware: {torque_limit_nm: 0.6}

`sensors` names the board's sensor set (protocol.messages.SENSOR_SET_NAMES): a board with the
SENSOR_SET capability gets SAMPLE_SENSORS with exactly these sensors every period, and the
session refuses a board whose SENSOR_SET parameter says otherwise. Absent or empty: the board
gets today's SAMPLE.

Without a board file the bench assumes a board written from SPEC.md alone: it pushes only the
required parameters and lets plans set any standard one (``spec_board``).
"""
from __future__ import annotations

import difflib
import math
import re
from pathlib import Path
from typing import Any

from configfile.dataclass_methods import dataclass
from configfile.schema import NAME, NUMBER, SchemaChecker, obj
from configfile.source import ConfigError, YamlDocument, load_yaml

from protocol.messages import SENSOR_SET_NAMES

from hil.boards.standard import (
    CAPABILITY_NAMES, REQUIRED_PARAMS, STANDARD_PARAMS, VENDOR_ID_MAX, VENDOR_ID_MIN, ParamSpec)

_SNAKE = re.compile(r"^[a-z][a-z0-9_]*$")
_FLOAT32_MAX = 3.4028234663852886e38

_VENDOR_SCHEMA = obj({
    "id": {"type": "integer", "minimum": VENDOR_ID_MIN, "maximum": VENDOR_ID_MAX},
    "unit": NAME, "min": NUMBER, "max": NUMBER, "default": NUMBER,
    "description": {"type": "string"}, "read_only": {"type": "boolean"},
}, required=("id", "unit"))
_SETTING_SCHEMA = {"oneOf": [NUMBER, obj({"value": NUMBER, "optional": {"type": "boolean"}},
                                         required=("value",))]}
_SETTINGS_SCHEMA = {"type": ["object", "null"], "additionalProperties": _SETTING_SCHEMA}
BOARD_SCHEMA = obj({
    "name": NAME,
    "description": {"type": "string"},
    "capabilities": {"type": "array", "items": {"enum": list(CAPABILITY_NAMES)},
                     "uniqueItems": True},
    "parameters": obj({
        "standard": {"type": "array", "items": {"type": "string"}, "uniqueItems": True},
        "vendor": {"type": ["object", "null"], "additionalProperties": _VENDOR_SCHEMA},
    }),
    "sensors": {"type": ["array", "null"], "items": {"type": "string"}},
    "settings": _SETTINGS_SCHEMA,
    "profile_settings": {"type": ["object", "null"], "additionalProperties": _SETTINGS_SCHEMA},
}, required=("name",))


@dataclass(frozen=True)
class Setting:
    """A value the bench pushes at session start. A required one refused ends the session;
    an optional one answered UNKNOWN is logged and the session goes on."""

    name: str
    value: float
    optional: bool = False


@dataclass(frozen=True)
class BoardFile:
    """A board: the parameters it takes and what the bench pushes to it."""

    name: str
    source: str
    parameters: dict[str, ParamSpec]
    settings: tuple[Setting, ...] = ()
    profile_settings: dict[str, tuple[Setting, ...]] | None = None
    capabilities: tuple[str, ...] = ()
    description: str = ""
    # the sensor set's names (SENSOR_SET_NAMES), in the file's order; () = today's SAMPLE
    sensors: tuple[str, ...] = ()

    @property
    def sensor_set(self) -> int:
        """The `sensors:` key as SENSOR_SET's bit mask (0: none given, today's SAMPLE)."""
        return sensor_set_mask(self.sensors)

    def param(self, name: str) -> ParamSpec:
        """The parameter called `name`; KeyError with a sentence that names the board file."""
        spec = self.parameters.get(name)
        if spec is None:
            raise KeyError(self.unknown_param_message(name))
        return spec

    def unknown_param_message(self, name: str) -> str:
        known = sorted(self.parameters)
        close = difflib.get_close_matches(name, known, n=1, cutoff=0.75)
        hint = f"; did you mean '{close[0]}'?" if close else ""
        if name in STANDARD_PARAMS:
            return (f"board '{self.name}' ({self.source}) does not take the standard parameter "
                    f"'{name}' (its board file does not list it under parameters.standard){hint}")
        return (f"unknown board parameter '{name}': not a SPEC parameter and not one of board "
                f"'{self.name}''s own ({self.source}){hint}")

    def settings_for(self, profile_label: str | None) -> tuple[Setting, ...]:
        """The settings pushed on a profile: the common ones, then the profile's own (a name
        given twice takes the profile's value, at the common one's place)."""
        merged = {s.name: s for s in self.settings}
        for s in (self.profile_settings or {}).get(_profile_key(profile_label), ()):
            merged[s.name] = s
        return tuple(merged.values())

    def check_value(self, name: str, value: float) -> str | None:
        """Why `value` cannot be set on parameter `name`, or None."""
        spec = self.parameters.get(name)
        if spec is None:
            return self.unknown_param_message(name)
        if spec.read_only:
            return f"parameter '{name}' is read-only: the board reports it, the bench cannot set it"
        if not math.isfinite(value) or abs(value) > _FLOAT32_MAX:
            return f"parameter '{name}' = {value!r} is not a finite float32"
        problem = spec.problem(value)
        return f"parameter '{name}' = {value:g} is {problem}" if problem else None

    def with_settings(self, extra: dict[str, float] | None) -> "BoardFile":
        """This board with more settings, on every profile (a name it already sets takes the
        new value, also over profile_settings): for tests and benchmarks that vary a setting.
        ValueError when a name or value does not fit the board."""
        if not extra:
            return self
        merged = {s.name: s for s in self.settings}
        for name, value in extra.items():
            problem = self.check_value(name, float(value))
            if problem is not None:
                raise ValueError(problem)
            merged[name] = Setting(name, float(value))
        per_profile = {label: tuple(s for s in block if s.name not in extra)
                       for label, block in (self.profile_settings or {}).items()}
        return BoardFile(name=self.name, source=self.source, parameters=self.parameters,
                         settings=tuple(merged.values()), profile_settings=per_profile,
                         capabilities=self.capabilities, description=self.description,
                         sensors=self.sensors)

    def summary(self) -> dict[str, Any]:
        """Plain data for logs and result.json."""
        return {"name": self.name, "source": self.source,
                "capabilities": list(self.capabilities),
                **({"sensors": list(self.sensors)} if self.sensors else {}),
                "vendor_parameters": {n: {"id": p.id, "unit": p.unit}
                                      for n, p in self.parameters.items() if p.vendor}}


def sensor_set_mask(names) -> int:
    """SENSOR_SET's bit mask of sensor names (each one of SENSOR_SET_NAMES)."""
    mask = 0
    for name in names:
        mask |= SENSOR_SET_NAMES[name]
    return mask


def sensor_set_names(mask: int) -> list[str]:
    """The names of a SENSOR_SET bit mask's known bits, in bit order (unknown bits as hex)."""
    names = [name for name, bit in sorted(SENSOR_SET_NAMES.items(), key=lambda kv: kv[1])
             if mask & bit]
    rest = mask & ~sensor_set_mask(SENSOR_SET_NAMES)
    return names + ([f"0x{rest:04x}"] if rest else [])


def _profile_key(label: str | None) -> str:
    """A profile's key in profile_settings: its name, or a profile file's stem."""
    if label is None or str(label).startswith("<"):     # "<defaults>": the paper's profile
        return "paper"
    text = str(label)
    return Path(text).stem if text.endswith((".yaml", ".yml")) else text


def spec_board() -> BoardFile:
    """A board written from SPEC.md alone: the required parameters pushed, every standard one
    settable by a plan, no vendor parameters."""
    return BoardFile(name="a SPEC board (no board file)", source="<no board file>",
                     parameters=dict(STANDARD_PARAMS))


def load_board(path: str | Path) -> BoardFile:
    """Reads and checks a board file; ConfigError naming the file, line and key of a bad value."""
    doc = load_yaml(path)
    data = doc.data
    if not isinstance(data, dict):
        raise doc.error((), "a board file is a mapping with at least `name`")
    SchemaChecker(doc).check(BOARD_SCHEMA, data)
    params = _parameters(doc, data.get("parameters") or {})
    sensors = _sensors(doc, data.get("sensors") or ())
    board = BoardFile(name=data["name"], source=doc.source, parameters=params,
                      capabilities=tuple(data.get("capabilities") or ()),
                      description=data.get("description", ""),
                      sensors=sensors)
    settings = _settings(doc, board, data.get("settings"), ("settings",))
    per_profile = {str(label): _settings(doc, board, block, ("profile_settings", label))
                   for label, block in (data.get("profile_settings") or {}).items()}
    return BoardFile(name=board.name, source=board.source, parameters=params,
                     settings=settings, profile_settings=per_profile,
                     capabilities=board.capabilities, description=board.description,
                     sensors=board.sensors)


def _sensors(doc: YamlDocument, names) -> tuple[str, ...]:
    """The `sensors:` list: each a known sensor name, none twice (file, line and key)."""
    seen: list[str] = []
    for i, name in enumerate(names):
        if name not in SENSOR_SET_NAMES:
            close = difflib.get_close_matches(str(name), list(SENSOR_SET_NAMES), n=1, cutoff=0.6)
            hint = (f"; did you mean '{close[0]}'?" if close else
                    f" (known: {', '.join(SENSOR_SET_NAMES)})")
            raise doc.error(("sensors", i), f"'{name}' is not a sensor{hint}")
        if name in seen:
            raise doc.error(("sensors", i), f"sensor '{name}' is listed twice")
        seen.append(name)
    return tuple(seen)


def _parameters(doc: YamlDocument, section: dict) -> dict[str, ParamSpec]:
    params = {name: STANDARD_PARAMS[name] for name in REQUIRED_PARAMS}
    params["control_step_cycles"] = STANDARD_PARAMS["control_step_cycles"]
    for i, name in enumerate(section.get("standard") or ()):
        if name not in STANDARD_PARAMS:
            close = difflib.get_close_matches(name, list(STANDARD_PARAMS), n=1, cutoff=0.75)
            hint = f"; did you mean '{close[0]}'?" if close else " (SPEC.md section 8)"
            raise doc.error(("parameters", "standard", i),
                            f"'{name}' is not a standard parameter{hint}")
        params[name] = STANDARD_PARAMS[name]
    ids = {p.id: p.name for p in STANDARD_PARAMS.values()}
    for name, body in (section.get("vendor") or {}).items():
        path = ("parameters", "vendor", name)
        if not _SNAKE.match(str(name)):
            raise doc.error(path, "a parameter name is lower_snake_case, ending in its unit "
                                  "where it has one (e.g. velocity_lpf_hz)")
        if name in STANDARD_PARAMS:
            raise doc.error(path, f"'{name}' is a standard parameter (SPEC id "
                                  f"{STANDARD_PARAMS[name].id}): list it under parameters.standard")
        if body["id"] in ids:
            raise doc.error(path + ("id",), f"id {body['id']} is already '{ids[body['id']]}'")
        ids[body["id"]] = name
        spec = ParamSpec(name=name, id=body["id"], unit=body["unit"],
                         description=body.get("description", ""), minimum=body.get("min"),
                         maximum=body.get("max"), default=body.get("default"),
                         read_only=bool(body.get("read_only", False)), vendor=True)
        if spec.minimum is not None and spec.maximum is not None and spec.minimum > spec.maximum:
            raise doc.error(path + ("min",), f"min {spec.minimum:g} is above max {spec.maximum:g}")
        if spec.default is not None and spec.problem(spec.default):
            raise doc.error(path + ("default",), f"default {spec.default:g} is "
                                                 f"{spec.problem(spec.default)}")
        params[name] = spec
    return params


def _settings(doc: YamlDocument, board: BoardFile, block: Any, path: tuple) -> tuple[Setting, ...]:
    out = []
    for name, body in (block or {}).items():
        value = body["value"] if isinstance(body, dict) else body
        setting = Setting(name=name, value=float(value),
                          optional=bool(body.get("optional", False)) if isinstance(body, dict)
                          else False)
        problem = board.check_value(name, setting.value)
        if problem is not None:
            raise doc.error(path + (name,), problem)
        out.append(setting)
    return tuple(out)


def load_board_or_spec(path: str | Path | None) -> BoardFile:
    return spec_board() if path is None else load_board(path)


__all__ = ["BoardFile", "Setting", "load_board", "spec_board", "load_board_or_spec",
           "ConfigError", "sensor_set_mask", "sensor_set_names"]
