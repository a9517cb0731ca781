"""Structure checks for configuration files, declared as JSON Schema and reported by line.

One way of declaring what a file may hold, for plans and profiles alike: a JSON Schema
(Draft 2020-12, checked by the `jsonschema` package rather than by hand-written walkers; a
quick walker only accepts, first, what is certainly valid, so a valid file does not pay for
jsonschema's import),
built from the small blocks below or, for a parameter dataclass, derived from its `param()`
fields by `dataclass_schema`. `SchemaChecker` runs a schema on a part of a located YAML
document and turns the first error (the earliest in the file) into a `ConfigError` that names
the file, the line and the key, in words a person reads ("unknown key 'speed_rmp'; did you
mean 'speed_rpm'?").
"""
from __future__ import annotations

import dataclasses
import re
from typing import TYPE_CHECKING, Any, Callable, Iterable, Mapping

from configfile.fields import type_hints
from configfile.source import ConfigError, KeyPath, YamlDocument

if TYPE_CHECKING:
    import jsonschema

NUMBER = {"type": "number"}
POSITIVE = {"type": "number", "exclusiveMinimum": 0}
NON_NEGATIVE = {"type": "number", "minimum": 0}
FRACTION = {"type": "number", "minimum": 0, "maximum": 1}
POSITIVE_INT = {"type": "integer", "minimum": 1}
BOOLEAN = {"type": "boolean"}
NAME = {"type": "string", "minLength": 1}


def obj(props: dict, required: Iterable[str] = (), min_props: int = 0) -> dict:
    """A mapping with exactly these keys (unknown keys are errors)."""
    schema: dict[str, Any] = {"type": "object", "properties": props, "additionalProperties": False}
    if required:
        schema["required"] = list(required)
    if min_props:
        schema["minProperties"] = min_props
    return schema


def nullable(schema: dict) -> dict:
    """The same mapping, or nothing (an empty YAML section)."""
    return {**schema, "type": [schema["type"], "null"]}


def dataclass_schema(cls: type) -> dict:
    """The JSON Schema of a parameter dataclass (configfile.fields.param fields), nested
    dataclasses included. It checks the structure (known keys, mappings where sections are);
    values are converted and bound-checked by configfile.fields.coerce, which also accepts
    what YAML 1.1 leaves as text but is plainly a number (50e-6)."""
    hints = type_hints(cls)
    props: dict[str, Any] = {}
    for f in dataclasses.fields(cls):
        hint = hints[f.name]
        if dataclasses.is_dataclass(hint):
            props[f.name] = nullable(dataclass_schema(hint))
        else:
            props[f.name] = {}
    return obj(props)


_TYPE_WORDS = {"number": "a number", "integer": "an integer", "string": "a string",
               "boolean": "true or false", "object": "a mapping (key: value)", "array": "a list"}


def python_type(value: Any) -> str:
    """What a YAML value is, in words."""
    if isinstance(value, bool):
        return "a boolean"
    if isinstance(value, (int, float)):
        return "a number"
    if isinstance(value, str):
        return "a string"
    if isinstance(value, dict):
        return "a mapping"
    if isinstance(value, list):
        return "a list"
    return "nothing" if value is None else type(value).__name__


# --------------------------------------------------------------------------- quick acceptance
# jsonschema's import (referencing, attrs, its format checkers, the meta-schemas) is about a
# sixth of a short `hil run`, and it runs on every profile and plan although nearly every
# document is valid. The walker below decides "valid" for the keywords and values these
# schemas use, with jsonschema's semantics; anything else (an invalid document, a keyword or a
# value it does not model) goes to jsonschema, which alone words the errors. So a valid
# document loads without jsonschema and an invalid one fails exactly as before
# (tests/test_quick_schema.py holds the walker to jsonschema on every schema of plans and
# profiles). SchemaChecker.check runs it first.

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


class SchemaChecker:
    """Runs JSON schemas on parts of a YamlDocument and turns errors into ConfigErrors.

    `pattern_words` maps a schema's regular expressions to what a person should write."""

    def __init__(self, doc: YamlDocument, pattern_words: Mapping[str, str] | None = None,
                 error=None):
        self.doc = doc
        self.pattern_words = dict(pattern_words or {})
        self._error = error

    def error(self, path: KeyPath, message: str) -> ConfigError:
        if self._error is not None:
            return self._error(path, message)
        return self.doc.error(path, message)

    def check(self, schema: dict, value: Any, path: KeyPath = ()) -> None:
        if schema_accepts(schema, value):
            return
        # Imported at the first document the quick check does not accept, not with this
        # module: the schemas above are plain data that plans, profiles and the CLI build at
        # import, and jsonschema's own import (referencing, attrs, its format checkers, the
        # meta-schemas) is ~0.1 s.
        from jsonschema import Draft202012Validator

        errors = list(Draft202012Validator(schema).iter_errors(value))
        if not errors:
            return

        def where(e: jsonschema.ValidationError) -> tuple[int, int]:
            p = path + tuple(e.absolute_path)
            return (self.doc.line_of(p) or 0, -len(p))
        first = min(errors, key=where)
        raise self._convert(first, path)

    def _convert(self, e: jsonschema.ValidationError, base: KeyPath) -> ConfigError:
        path = base + tuple(e.absolute_path)
        v = e.validator
        inst = e.instance
        if v == "additionalProperties" and isinstance(inst, dict):
            allowed = list(e.schema.get("properties", {}))
            extra = [k for k in inst if k not in allowed]
            key = extra[0] if extra else None
            import difflib

            close = difflib.get_close_matches(str(key), allowed, n=1, cutoff=0.75) if key else []
            expected = (f"; did you mean '{close[0]}'?" if close else
                        f"; expected one of: {', '.join(allowed)}" if allowed else "")
            if key is None:
                return self.error(path, e.message)
            return self.error(path + (key,), f"unknown key '{key}'{expected}")
        if v == "required":
            missing = [k for k in e.validator_value if not (isinstance(inst, dict) and k in inst)]
            return self.error(path, f"missing required key '{missing[0]}'")
        if v == "type":
            want = e.validator_value
            want_text = " or ".join(_TYPE_WORDS.get(w, w) for w in (want if isinstance(want, list) else [want]))
            got = f"{python_type(inst)} ({inst!r})"
            hint = ""
            if isinstance(inst, str) and want in ("number", "integer") and _looks_numeric(inst):
                hint = (" - YAML reads an exponent without a decimal point as text: "
                        f"write {_float_hint(inst)}")
            return self.error(path, f"expected {want_text}, got {got}{hint}")
        if v == "enum":
            return self.error(path, f"expected one of: {', '.join(map(str, e.validator_value))}; "
                                    f"got {inst!r}")
        if v == "exclusiveMinimum":
            return self.error(path, f"must be greater than {e.validator_value}, got {inst!r}")
        if v == "minimum":
            return self.error(path, f"must be at least {e.validator_value}, got {inst!r}")
        if v == "maximum":
            return self.error(path, f"must be at most {e.validator_value}, got {inst!r}")
        if v == "minProperties":
            allowed = list(e.schema.get("properties", {}))
            hint = f": {', '.join(allowed)}" if allowed else ""
            return self.error(path, f"needs at least {e.validator_value} key(s){hint}")
        if v == "minItems":
            return self.error(path, f"needs at least {e.validator_value} item(s)")
        if v == "maxItems":
            return self.error(path, f"takes at most {e.validator_value} item(s)")
        if v == "minLength":
            return self.error(path, "must not be empty")
        if v == "pattern":
            words = self.pattern_words.get(e.validator_value, e.validator_value)
            return self.error(path, f"{inst!r} is not a valid value (expected {words})")
        if v == "oneOf":
            return self.error(path, f"expected a signal name or a quantity {{value, unit}}, got "
                                    f"{python_type(inst)} ({inst!r})")
        return self.error(path, e.message)


def _looks_numeric(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _float_hint(text: str) -> str:
    mant, _, exp = text.lower().partition("e")
    if "." not in mant:
        mant += ".0"
    return f"{mant}e{exp}" if exp else mant


__all__ = ["NUMBER", "POSITIVE", "NON_NEGATIVE", "FRACTION", "POSITIVE_INT", "BOOLEAN", "NAME",
           "obj", "nullable", "dataclass_schema", "python_type", "SchemaChecker"]
