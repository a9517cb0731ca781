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
import dataclasses
from dataclasses import field
from pathlib import Path
from typing import Any, Callable

from configfile.dataclass_methods import dataclass
from configfile.schema import SchemaChecker, dataclass_schema, nullable, obj
from configfile.source import ConfigError, YamlDocument, format_key, load_yaml

from plant_rt.dc_link import DcLinkParams
from plant_rt.inverter import InverterParams
from plant_rt.load import LoadParams
from plant_rt.motor import MotorParams
from plant_rt.sensors import SensorParams
from plant_rt.thermal import ThermalParams
from configfile.fields import coerce, param, to_float, type_hints



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
    thermal: ThermalParams = field(default_factory=ThermalParams)
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


SECTIONS = {f.name for f in dataclasses.fields(BenchProfile)} - {"source"}


def profile_schema() -> dict:
    """The profile's structure as JSON Schema (configfile.schema): every section a parameter
    dataclass, `session` a mapping the bench checks."""
    hints = type_hints(BenchProfile)
    sections = {name: nullable(dataclass_schema(hints[name]))
                for name in SECTIONS if name != "session"}
    # A profile says what the bench emulates; what a board is told lives in its board file.
    sections["controller"] = {"description": "moved to board files"}
    sections["session"] = {"type": ["object", "null"]}
    return obj(sections)


def default_profile_path() -> Path:
    return Path(__file__).resolve().parent / "profiles" / "paper.yaml"


def load_profile(path: str | Path | None = None,
                 overrides: dict[str, Any] | None = None,
                 session_schema: dict | None = None) -> BenchProfile:
    """Reads and validates a bench profile; raises configfile.ConfigError on a bad value.

    `session_schema` is the bench's JSON Schema of the `session` section (without it,
    `session` must be a mapping)."""
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
        SchemaChecker(doc, error=err).check(schema, data)
    return build_profile(data, _error_factory(doc, marks), doc.source)


def build_profile(data: Any, err: Callable[[tuple, str], ConfigError],
                  source: str = "<data>") -> BenchProfile:
    """Validates already-parsed profile data; `err(key_path, message)` makes the errors."""
    if not isinstance(data, dict):
        raise err((), "a bench profile is a mapping of sections "
                      f"({', '.join(sorted(SECTIONS))})")
    hints = type_hints(BenchProfile)
    sections: dict[str, Any] = {}
    for key, value in data.items():
        if key == "controller":
            raise err((key,), "a bench profile no longer carries what the board is told: move "
                              "these parameters to a board file's `settings` (docs/boards.md) "
                              "and give it with `hil run --board FILE` or a plan's `board:`")
        if key not in SECTIONS:
            raise err((key,), f"unknown section (known: {', '.join(sorted(SECTIONS))})")
        if key == "session":
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
    for key, message in profile.motor.problems():
        raise err(("motor", key), message)


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
