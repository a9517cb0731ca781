"""Formulas in a plan: the named values they read, and their evaluation before a run.

A plan may write any number whose unit is known as a formula (hil.plans.formula): a limit's
``low``/``high``/``marginal`` (in the limits' ``unit``), a quantity's ``value`` (in its
``unit``), a wait's ``value``/``tolerance``, and any key whose name ends in a unit
(``speed_ref_rpm``, ``duration_s``, ``torque_nm``, ...). It may also define ``constants``:

    constants:
      speed_start: {value: "0.5 * motor.rated_speed_rpm", unit: rpm}
      ramp_time: {value: "motor.inertia_kgm2 * (speed_target - speed_start) / board.torque_limit_nm", unit: ms}

each a number or a formula over the values before it. A formula reads:

- the bench profile of the run: ``motor.inertia_kgm2``, ``timing.control_period_s``,
  ``dc_link.source_voltage_v``, ``sensors.current.a_per_count``, ... (every number of
  plant_rt's profile, its unit from its name);
- the board's parameters in force: ``board.torque_limit_nm`` is the board file's setting for
  the profile of the run, else (SPEC 8.1's required parameters) the value the bench pushes
  from the profile, else SPEC 8.1's default (hil.boards.standard.SPEC_DEFAULTS); a plan's own
  ``param_set`` later in the run is not seen;
- the plan's constants, and ``pi``.

The numbers are substituted into the plan's data before it is validated (so every other rule
of the format applies to them), once with the plan's first profile when it is loaded (every
profile it lists is evaluated, so a formula that fails on one fails `hil plans`), and again
by the runner with the profile and board file of each run (hil.run.runner): a sweep's
sampled profile, `--profile` and `--board` move them. Every number that came from a formula
keeps its Derivation (formula, value, unit, inputs) for the report and result.json.
"""
from __future__ import annotations

import dataclasses
import re
from collections.abc import Mapping
from typing import Any

from configfile.source import KeyPath, YamlDocument
from hil.plans.formula import Derivation, FormulaError, evaluate, unit_si
from hil.plans.units import UnitError, canonical

# A key's unit from its name's ending (longest first).
_SUFFIX_UNITS: tuple[tuple[str, str], ...] = (
    ("_nm_per_rad_s", "Nm/(rad/s)"), ("_nm_per_rad", "Nm/rad"), ("_kgm2", "kgm^2"),
    ("_rad_s", "rad/s"), ("_rpm", "rpm"), ("_ohm", "ohm"), ("_wb", "Wb"), ("_nm", "Nm"),
    ("_hz", "Hz"), ("_rad", "rad"), ("_counts", "count"), ("_s", "s"), ("_v", "V"),
    ("_a", "A"), ("_h", "H"), ("_f", "F"),
    ("_k_per_w", "K/W"), ("_j_per_k", "J/K"), ("_per_k", "1/K"), ("_degc", "degC"),
)
# The units SPEC 8 writes its parameters in, as formulas read them.
_SPEC_UNITS = {"N m": "Nm", "N m/(rad/s)": "Nm/(rad/s)", "N m/rad": "Nm/rad", "A/count": "A",
               "V/count": "V", "period": "count", "cycle": "count",
               "degC/count": "degC"}
# Top-level keys whose strings are never formulas.
_NOT_FORMULAS = ("name", "description", "profile", "profiles", "overrides", "link", "board",
                 "mode", "constants")
_CONSTANT_NAME = re.compile(r"^[a-z][a-z0-9_]*$")
RESERVED_NAMES = ("timing", "motor", "inverter", "dc_link", "load", "sensors", "initial",
                  "thermal", "board", "pi", "sqrt", "min", "max", "abs", "exp", "log")


def suffix_unit(key: str) -> str | None:
    for suffix, unit_ in _SUFFIX_UNITS:
        if key.endswith(suffix):
            return unit_
    return None


def profile_values(profile) -> dict[str, tuple[float, str]]:
    """Every number of a bench profile by its dotted name, with its unit (from its name)."""
    out: dict[str, tuple[float, str]] = {}

    def walk(obj: Any, prefix: str) -> None:
        for f in dataclasses.fields(obj):
            value = getattr(obj, f.name)
            name = f"{prefix}{f.name}"
            if dataclasses.is_dataclass(value):
                walk(value, name + ".")
            elif isinstance(value, (int, float)) and not isinstance(value, bool):
                out[name] = (float(value), suffix_unit(f.name) or "1")

    for section in ("timing", "motor", "inverter", "dc_link", "load", "sensors", "initial",
                    "thermal"):
        walk(getattr(profile, section), section + ".")
    return out


def board_values(profile, board, profile_label: str | None) -> dict[str, tuple[float, str]]:
    """SPEC 8's standard parameters in force on a board: its settings, else what the bench
    pushes from the profile, else SPEC 8.1's default."""
    from hil.boards.standard import SPEC_DEFAULTS, STANDARD_PARAMS, required_values

    values: dict[str, float] = dict(SPEC_DEFAULTS)
    values.update(required_values(profile))
    if board is not None:
        values.update({s.name: s.value for s in board.settings_for(profile_label)
                       if s.name in STANDARD_PARAMS})
    return {f"board.{name}": (float(values[name]), _SPEC_UNITS.get(spec.unit, spec.unit))
            for name, spec in STANDARD_PARAMS.items() if name in values}


def named_values(profile, board, profile_label: str | None) -> dict[str, tuple[float, str]]:
    values = profile_values(profile)
    values.update(board_values(profile, board, profile_label))
    return values


def has_formulas(data: Any) -> bool:
    """True when a plan's data has constants or a formula anywhere a number may be one."""
    if not isinstance(data, dict):
        return False
    if data.get("constants"):
        return True
    found = False

    def visit(path: KeyPath, parent: dict, key: Any, value: Any) -> Any:
        nonlocal found
        found = True
        return value
    _walk(data, (), visit)
    return found


def _site_unit(parent: dict, key: Any) -> str | None:
    """The unit a formula at parent[key] is in, or None when the key takes no formula."""
    if not isinstance(key, str):
        return None
    if key in ("low", "high", "marginal", "value", "tolerance") and isinstance(parent.get("unit"), str):
        return parent["unit"]
    if key in ("value", "tolerance") and isinstance(parent.get("signal"), str):
        from hil.plans.signals import SIGNAL_CATALOG

        return SIGNAL_CATALOG.get(parent["signal"])
    return suffix_unit(key)


def _plain_number(text: str) -> bool:
    """'8e-4': a number YAML read as text (no decimal point); the schema's error says so."""
    try:
        float(text)
    except ValueError:
        return False
    return True


def _walk(data: dict, path: KeyPath, visit) -> None:
    """Calls visit(path, parent, key, value) for every string at a formula site; its return
    value replaces the string."""
    def rec(node: Any, where: KeyPath) -> None:
        if isinstance(node, dict):
            for key in list(node):
                value = node[key]
                if not where and key in _NOT_FORMULAS:
                    continue
                if (isinstance(value, str) and _site_unit(node, key) is not None
                        and not _plain_number(value)):
                    node[key] = visit(where + (key,), node, key, value)
                else:
                    rec(value, where + (key,))
        elif isinstance(node, list):
            for i, value in enumerate(node):
                rec(value, where + (i,))
    rec(data, path)


def substitute(doc: YamlDocument, values: Mapping[str, tuple[float, str]]
               ) -> tuple[dict, dict[KeyPath, Derivation], dict[str, Derivation]]:
    """(the plan's data with every formula replaced by its number, the derivation of each by
    key path, the plan's constants as derivations); ConfigError naming file, line and key."""
    import copy

    data = copy.deepcopy(doc.data)
    env = dict(values)
    constants: dict[str, Derivation] = {}
    raw_constants = data.get("constants") or {}
    if not isinstance(raw_constants, dict):
        raise doc.error(("constants",), "constants is a mapping of NAME: {value, unit}")
    for name, raw in raw_constants.items():
        cpath: KeyPath = ("constants", name)
        if not isinstance(name, str) or not _CONSTANT_NAME.match(name) or name in RESERVED_NAMES:
            raise doc.error(cpath, f"'{name}' is not a constant's name (lower_snake_case, not "
                                   f"one of {', '.join(RESERVED_NAMES)})")
        if not isinstance(raw, dict) or set(raw) != {"value", "unit"}:
            raise doc.error(cpath, "a constant is {value: NUMBER or FORMULA, unit: UNIT}")
        try:
            unit_ = canonical(raw["unit"])
        except (UnitError, AttributeError) as exc:
            raise doc.error(cpath + ("unit",), str(exc)) from None
        value = raw["value"]
        if isinstance(value, str):
            try:
                d = _with_constants_inputs(evaluate(value, env, unit_), constants)
            except FormulaError as exc:
                raise doc.error(cpath + ("value",), str(exc)) from None
        elif isinstance(value, (int, float)) and not isinstance(value, bool):
            d = Derivation(str(value), float(value), unit_)
        else:
            raise doc.error(cpath + ("value",), "a constant's value is a number or a formula")
        constants[name] = d
        env[name] = (d.value, unit_)
        raw["value"] = d.value
        raw["unit"] = unit_
    derivations: dict[KeyPath, Derivation] = {}

    def visit(path: KeyPath, parent: dict, key: str, text: str) -> float:
        unit_ = _site_unit(parent, key)
        try:
            unit_si(unit_)
        except (UnitError, KeyError) as exc:
            raise doc.error(path, f"the formula's unit: {exc}") from None
        try:
            d = _with_constants_inputs(evaluate(text, env, unit_), constants)
        except FormulaError as exc:
            prefix = (f"expected a number, got a string ('{text}'), read as a formula: "
                      if text.strip().isidentifier() else "")
            raise doc.error(path, prefix + str(exc)) from None
        derivations[path] = d
        return d.value

    _walk(data, (), visit)
    return data, derivations, constants


def _with_constants_inputs(d: Derivation, constants: Mapping[str, Derivation]) -> Derivation:
    """d with the inputs of the constants it reads after each of them (a constant's own inputs
    already include those of the constants it reads): every value a limit depends on."""
    inputs = []
    for i in d.inputs:
        inputs.append(i)
        inputs.extend(constants[i.name].inputs if i.name in constants else ())
    unique = tuple(dict((i.name, i) for i in inputs).values())
    return dataclasses.replace(d, inputs=unique)


def plan_contexts(doc: YamlDocument, path, resolve_profile) -> list[tuple[str, Any, Any]]:
    """(label, profile, board) for every profile a plan's data lists, with its overrides and the
    board it names (else its link's): what the plan is evaluated against when it is loaded.
    resolve_profile(value, base_dir) -> a ref with .label and .path (hil.plans.format's)."""
    from pathlib import Path

    from hil.boards import load_board
    from hil.session.board_params import default_board, load_bench_profile

    data = doc.data
    base = Path(path).parent
    names: list[tuple[KeyPath, str]] = []
    if isinstance(data.get("profiles"), list):
        names = [(("profiles", i), v) for i, v in enumerate(data["profiles"])]
    elif isinstance(data.get("profile"), str):
        names = [(("profile",), data["profile"])]
    refs: list[tuple[str, Any]] = []
    for key, value in names:
        try:
            ref = resolve_profile(str(value), base)
        except ValueError as exc:
            raise doc.error(key, str(exc)) from None
        refs.append((ref.label, ref.path))
    if not refs:
        refs = [("paper", None)]
    overrides = data.get("overrides") if isinstance(data.get("overrides"), dict) else None
    if isinstance(data.get("board"), str):
        board_path = (base / data["board"]).resolve()
        if not board_path.is_file():
            raise doc.error(("board",), f"board file not found: {board_path}")
        board = load_board(board_path)
    else:
        board = default_board(data.get("link") if isinstance(data.get("link"), str) else None)
    return [(label, load_bench_profile(profile_path, overrides=overrides or None), board)
            for label, profile_path in refs]


__all__ = ["profile_values", "board_values", "named_values", "has_formulas", "substitute",
           "plan_contexts", "suffix_unit", "RESERVED_NAMES"]
