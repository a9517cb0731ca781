"""What a valid parameter value is: field constraints shared by the profile loader and the
runtime setters, so a value rejected in a YAML file is rejected the same way at run time.

Every parameter dataclass declares its fields with `param(...)`; `coerce(cls, name, value)`
converts a raw value (from YAML or a caller) to the field's type and checks its bounds,
raising `ValueError` with a message that names the constraint (the caller adds the file,
line and key).
"""
from __future__ import annotations

import dataclasses
import functools
import math
import re
import typing
from typing import Any

_NUMBER = re.compile(r"^[+-]?(\d+(\.\d*)?|\.\d+)([eE][+-]?\d+)?$")


def param(default: Any, *, gt: float | None = None, ge: float | None = None,
          lt: float | None = None, le: float | None = None,
          choices: tuple[str, ...] | None = None, kind: str | None = None) -> Any:
    """A dataclass field with bounds (gt/ge/lt/le), allowed strings or a special kind
    ("table": [t, value] rows; "triple": three numbers, one per phase, each within the bounds)."""
    meta = {"gt": gt, "ge": ge, "lt": lt, "le": le, "choices": choices, "kind": kind}
    if isinstance(default, (list, tuple)):
        return dataclasses.field(default_factory=lambda: tuple(default), metadata=meta)
    return dataclasses.field(default=default, metadata=meta)


@functools.cache
def type_hints(cls: type) -> dict[str, Any]:
    """typing.get_type_hints(cls), worked out once per class. Under `from __future__ import
    annotations` every annotation is a string that each get_type_hints call compiles and
    evaluates again: loading a profile asked 22 times for its 11 classes. The dict is shared:
    read it, do not change it."""
    return typing.get_type_hints(cls)


def field_map(cls: type) -> dict[str, dataclasses.Field]:
    return {f.name: f for f in dataclasses.fields(cls)}


def to_float(value: Any) -> float:
    if isinstance(value, bool):
        raise ValueError(f"expected a number, got {value!r}")
    if isinstance(value, (int, float)):
        result = float(value)
    elif isinstance(value, str) and _NUMBER.match(value.strip()):
        # YAML 1.1 reads 50e-6 (no decimal point) as a string: accept what is plainly a number.
        result = float(value)
    else:
        raise ValueError(f"expected a number, got {value!r}")
    if not math.isfinite(result):
        raise ValueError(f"expected a finite number, got {value!r}")
    return result


def _to_int(value: Any) -> int:
    number = to_float(value)
    if number != int(number):
        raise ValueError(f"expected a whole number, got {value!r}")
    return int(number)


def _table(value: Any) -> tuple[tuple[float, float], ...]:
    if not isinstance(value, (list, tuple)):
        raise ValueError(f"expected a list of [t_s, value] pairs, got {value!r}")
    rows = []
    for n, row in enumerate(value):
        if not isinstance(row, (list, tuple)) or len(row) != 2:
            raise ValueError(f"row {n}: expected a [t_s, value] pair, got {row!r}")
        t, v = to_float(row[0]), to_float(row[1])
        if rows and t < rows[-1][0]:
            raise ValueError(f"row {n}: times must not decrease ({t} after {rows[-1][0]})")
        rows.append((t, v))
    return tuple(rows)


def _triple(value: Any) -> tuple[float, float, float]:
    if not isinstance(value, (list, tuple)) or len(value) != 3:
        raise ValueError(f"expected a list of three numbers (phases a, b, c), got {value!r}")
    return to_float(value[0]), to_float(value[1]), to_float(value[2])


def coerce(cls: type, name: str, value: Any) -> Any:
    """Converts `value` to the type of field `name` of dataclass `cls` and checks its bounds."""
    fields = field_map(cls)
    if name not in fields:
        raise KeyError(name)
    f = fields[name]
    meta = f.metadata
    kind = meta.get("kind")
    ftype = f.type if isinstance(f.type, str) else getattr(f.type, "__name__", str(f.type))
    if kind == "table":
        return _table(value)
    if kind == "triple":        # one number per phase, each within the field's bounds
        values = _triple(value)
        for n, v in enumerate(values):
            _check_bounds(meta, v, f"element {n} ({v!r})")
        return values
    if ftype == "bool":
        if not isinstance(value, bool):
            raise ValueError(f"expected true or false, got {value!r}")
        return value
    if ftype == "str":
        if not isinstance(value, str):
            raise ValueError(f"expected a string, got {value!r}")
        choices = meta.get("choices")
        if choices and value not in choices:
            raise ValueError(f"must be one of {', '.join(choices)} (got {value!r})")
        return value
    if ftype == "int":
        result: float = _to_int(value)
    elif ftype == "float":
        result = to_float(value)
    else:
        raise TypeError(f"{cls.__name__}.{name}: unsupported field type {ftype}")
    _check_bounds(meta, result, repr(value))
    return result


def _check_bounds(meta: Any, result: float, shown: str) -> None:
    for key, op, text in (("gt", float.__gt__, ">"), ("ge", float.__ge__, ">="),
                          ("lt", float.__lt__, "<"), ("le", float.__le__, "<=")):
        bound = meta.get(key)
        if bound is not None and not op(float(result), float(bound)):
            raise ValueError(f"must be {text} {bound:g} (got {shown})")
