"""Limit formulas: a small, safe expression language over named values with units.

A plan may write a number as a formula, e.g.

    high: "0.8 * motor.inertia_kgm2 * delta_speed / board.torque_limit_nm"

over named values that each carry a unit (the bench profile's ``motor.*``, ``timing.*``, ...,
the board's parameters in force ``board.*``, the plan's ``constants``). The text is parsed
with Python's ``ast`` and only a whitelist is accepted: numbers, names (dotted), ``+ - * /
**``, unary minus, parentheses and the functions of ``FUNCTIONS``; anything else (calls of
other names, attributes of numbers, subscripts, comparisons, strings, lambdas...) is refused.
Nothing is ever executed by Python: the tree is walked here.

Units: every value is carried in SI with its dimension as exponents of (kg, m, s, A); the
angle is dimensionless (SI), so rpm is 2 pi / 60 s^-1 and Hz is 1 s^-1: an angular frequency
from a frequency is ``2 * pi * f``. Sums need equal dimensions, ``**`` a dimensionless
exponent, ``sqrt`` halves the exponents. The result must have the dimension of the unit it
is asked for (hil.plans.units), and is then expressed in it.
"""
from __future__ import annotations

import ast
import difflib
import math
from collections.abc import Mapping
from fractions import Fraction

from configfile.dataclass_methods import dataclass
from hil.plans.units import UnitError, unit as lookup_unit

Dims = tuple[Fraction, Fraction, Fraction, Fraction, Fraction]     # kg, m, s, A, K
_BASE = ("kg", "m", "s", "A", "K")


def _d(kg: int = 0, m: int = 0, s: int = 0, a: int = 0, k: int = 0) -> Dims:
    return (Fraction(kg), Fraction(m), Fraction(s), Fraction(a), Fraction(k))


NONE = _d()
# hil.plans.units' dimensions in SI base exponents (angle dimensionless).
DIMENSIONS: dict[str, Dims] = {
    "dimensionless": NONE, "angle": NONE,
    "time": _d(s=1), "angular_velocity": _d(s=-1), "frequency": _d(s=-1),
    "current": _d(a=1), "voltage": _d(1, 2, -3, -1), "torque": _d(1, 2, -2),
    "flux_linkage": _d(1, 2, -2, -1), "resistance": _d(1, 2, -3, -2),
    "inductance": _d(1, 2, -2, -2), "power": _d(1, 2, -3), "inertia": _d(1, 2),
    "temperature": _d(k=1),     # degC only: a temperature difference and a temperature alike
}
# Units of named values that plans do not write limits in (profile and board parameters).
_VALUE_UNITS: dict[str, tuple[float, Dims]] = {
    "F": (1.0, _d(-1, -2, 4, 2)),
    "Nm/(rad/s)": (1.0, _d(1, 2, -1)),
    "Nm/rad": (1.0, _d(1, 2, -2)),
    # the thermal model's (profile `thermal:`)
    "K/W": (1.0, _d(-1, -2, 3, 0, 1)),
    "J/K": (1.0, _d(1, 2, -2, 0, -1)),
    "1/K": (1.0, _d(k=-1)),
}


class FormulaError(ValueError):
    """A formula that is not allowed, names an unknown value, mixes units, or has no finite value."""


def unit_si(symbol: str) -> tuple[float, Dims]:
    """(scale to SI, dimension) of a unit symbol."""
    if symbol in _VALUE_UNITS:
        return _VALUE_UNITS[symbol]
    u = lookup_unit(symbol)
    return u.scale_to_si, DIMENSIONS[u.dimension]


def describe_dims(dims: Dims) -> str:
    parts = []
    for base, exp in zip(_BASE, dims):
        if exp == 1:
            parts.append(base)
        elif exp != 0:
            parts.append(f"{base}^{exp}")
    return " ".join(parts) or "dimensionless"


@dataclass(frozen=True)
class Input:
    """A named value a formula read: its name, value and unit as the source gives them."""

    name: str
    value: float
    unit: str

    def to_json(self) -> dict:
        return {"name": self.name, "value": self.value, "unit": self.unit}


@dataclass(frozen=True)
class Derivation:
    """A number a formula gave: the formula, its value in `unit`, and every input it read."""

    formula: str
    value: float
    unit: str
    inputs: tuple[Input, ...] = ()

    def to_json(self) -> dict:
        return {"formula": self.formula, "value": self.value, "unit": self.unit,
                "inputs": [i.to_json() for i in self.inputs]}

    @classmethod
    def from_json(cls, data: dict) -> "Derivation":
        return cls(formula=data["formula"], value=float(data["value"]), unit=data["unit"],
                   inputs=tuple(Input(i["name"], float(i["value"]), i["unit"])
                                for i in data.get("inputs", ())))

    def describe(self) -> str:
        u = "" if self.unit == "1" else f" {self.unit}"
        inputs = ", ".join(f"{i.name} = {i.value:.6g}{'' if i.unit == '1' else ' ' + i.unit}"
                           for i in self.inputs)
        return f"{self.formula} = {self.value:.6g}{u}" + (f" ({inputs})" if inputs else "")


# --------------------------------------------------------------------------- parsing
_BINOPS = (ast.Add, ast.Sub, ast.Mult, ast.Div, ast.Pow)
_UNARY = (ast.USub, ast.UAdd)
FUNCTIONS = ("sqrt", "min", "max", "abs", "exp", "log")
MAX_LENGTH = 500        # keeps the tree shallow: the walks below recurse
CONSTANTS = {"pi": math.pi}


def _dotted(node: ast.AST) -> str | None:
    if isinstance(node, ast.Name):
        return node.id
    if isinstance(node, ast.Attribute):
        base = _dotted(node.value)
        return None if base is None else f"{base}.{node.attr}"
    return None


def parse(text: str) -> ast.Expression:
    """The checked syntax tree of a formula; FormulaError for anything outside the whitelist."""
    if not isinstance(text, str) or not text.strip():
        raise FormulaError("a formula is a non-empty string")
    if len(text) > MAX_LENGTH:
        raise FormulaError(f"a formula is at most {MAX_LENGTH} characters")
    try:
        tree = ast.parse(text.strip(), mode="eval")
        _check_node(tree.body, text)
    except SyntaxError as exc:
        raise FormulaError(f"formula '{text}' is not an expression: {exc.msg}") from None
    except (RecursionError, MemoryError):
        raise FormulaError(f"formula '{text[:60]}...' is nested too deeply") from None
    return tree


def _check_node(node: ast.AST, text: str) -> None:
    def refuse(what: str) -> FormulaError:
        return FormulaError(f"formula '{text}': {what} is not allowed (numbers, names, "
                            f"+ - * / **, unary minus, parentheses and "
                            f"{', '.join(FUNCTIONS)}, pi)")
    if isinstance(node, ast.Constant):
        if isinstance(node.value, bool) or not isinstance(node.value, (int, float)):
            raise refuse(f"the constant {node.value!r}")
        return
    if isinstance(node, (ast.Name, ast.Attribute)):
        name = _dotted(node)
        if name is None:
            raise refuse("an attribute of something that is not a name")
        if "__" in name:
            raise refuse(f"the name '{name}'")
        return
    if isinstance(node, ast.BinOp):
        if not isinstance(node.op, _BINOPS):
            raise refuse(f"the operator {type(node.op).__name__}")
        _check_node(node.left, text)
        _check_node(node.right, text)
        return
    if isinstance(node, ast.UnaryOp):
        if not isinstance(node.op, _UNARY):
            raise refuse(f"the operator {type(node.op).__name__}")
        _check_node(node.operand, text)
        return
    if isinstance(node, ast.Call):
        if not isinstance(node.func, ast.Name) or node.func.id not in FUNCTIONS:
            raise refuse(f"calling '{ast.unparse(node.func)}'")
        if node.keywords:
            raise refuse("a keyword argument")
        if not node.args:
            raise FormulaError(f"formula '{text}': {node.func.id}() needs an argument")
        for arg in node.args:
            if isinstance(arg, ast.Starred):
                raise refuse("a starred argument")
            _check_node(arg, text)
        return
    raise refuse(f"'{ast.unparse(node)}' ({type(node).__name__})")


def names_in(text: str) -> tuple[str, ...]:
    """The named values a formula reads, in order of first use."""
    out: list[str] = []
    for node in ast.walk(parse(text).body):
        if isinstance(node, (ast.Name, ast.Attribute)):
            name = _dotted(node)
            if name is not None and not (isinstance(node, ast.Name) and node.id in FUNCTIONS):
                out.append(name)
    # ast.walk also yields the inner parts of a dotted name: keep the longest ones.
    full = [n for n in out if not any(o != n and o.startswith(n + ".") for o in out)]
    return tuple(dict.fromkeys(full))


# --------------------------------------------------------------------------- evaluation
class _Eval:
    def __init__(self, text: str, values: Mapping[str, tuple[float, str]]):
        self.text, self.values = text, values
        self.inputs: dict[str, Input] = {}

    def err(self, message: str) -> FormulaError:
        return FormulaError(f"formula '{self.text}': {message}")

    def __call__(self, node: ast.AST) -> tuple[float, Dims]:
        if isinstance(node, ast.Constant):
            return float(node.value), NONE
        if isinstance(node, (ast.Name, ast.Attribute)):
            return self.name(_dotted(node))
        if isinstance(node, ast.UnaryOp):
            v, d = self(node.operand)
            return (-v if isinstance(node.op, ast.USub) else v), d
        if isinstance(node, ast.BinOp):
            return self.binop(node)
        if isinstance(node, ast.Call):
            return self.call(node)
        raise self.err(f"'{ast.unparse(node)}' is not allowed")   # parse() refused it already

    def name(self, name: str) -> tuple[float, Dims]:
        if name in CONSTANTS:
            return CONSTANTS[name], NONE
        if name not in self.values:
            close = difflib.get_close_matches(name, list(self.values), n=1, cutoff=0.6)
            group = name.split(".", 1)[0] + "."
            same = sorted(n for n in self.values if n.startswith(group))
            if close:
                hint = f"; did you mean '{close[0]}'?"
            elif same:
                hint = f"; names in '{group[:-1]}': {', '.join(same)}"
            else:
                hint = ("; names start with motor., timing., dc_link., inverter., load., "
                        "sensors., initial., thermal., board., or are the plan's constants")
            raise self.err(f"unknown name '{name}'{hint}")
        value, unit_ = self.values[name]
        scale, dims = unit_si(unit_)
        self.inputs.setdefault(name, Input(name, float(value), unit_))
        return float(value) * scale, dims

    def binop(self, node: ast.BinOp) -> tuple[float, Dims]:
        (a, da), (b, db) = self(node.left), self(node.right)
        op = node.op
        if isinstance(op, (ast.Add, ast.Sub)):
            if da != db:
                raise self.err(f"'{ast.unparse(node)}' adds {describe_dims(da)} and "
                               f"{describe_dims(db)}")
            return (a + b if isinstance(op, ast.Add) else a - b), da
        if isinstance(op, ast.Mult):
            return a * b, tuple(x + y for x, y in zip(da, db))
        if isinstance(op, ast.Div):
            if b == 0:
                raise self.err(f"division by zero: '{ast.unparse(node.right)}' is 0")
            return a / b, tuple(x - y for x, y in zip(da, db))
        # power: a dimensionless exponent; a fixed one (no names) when the base has a unit
        if db != NONE:
            raise self.err(f"the exponent '{ast.unparse(node.right)}' has a unit "
                           f"({describe_dims(db)})")
        if da != NONE and names_in(ast.unparse(node.right)):
            raise self.err(f"the exponent '{ast.unparse(node.right)}' of a value with a unit "
                           f"must be a fixed number")
        try:
            value = a ** b
        except (OverflowError, ZeroDivisionError) as exc:
            raise self.err(f"'{ast.unparse(node)}': {exc}") from None
        if isinstance(value, complex):
            raise self.err(f"'{ast.unparse(node)}' has no real value")
        exp = Fraction(b).limit_denominator(1000)
        return value, tuple(x * exp for x in da)

    def call(self, node: ast.Call) -> tuple[float, Dims]:
        fn = node.func.id
        args = [self(a) for a in node.args]
        where = ast.unparse(node)
        if fn in ("min", "max"):
            dims = args[0][1]
            if any(d != dims for _, d in args):
                raise self.err(f"'{where}' compares values of different units")
            pick = min if fn == "min" else max
            return pick(v for v, _ in args), dims
        if len(args) != 1:
            raise self.err(f"{fn}() takes one argument, got {len(args)}")
        v, d = args[0]
        if fn == "abs":
            return abs(v), d
        if fn == "sqrt":
            if v < 0:
                raise self.err(f"'{where}': square root of a negative number ({v:g})")
            return math.sqrt(v), tuple(x / 2 for x in d)
        if d != NONE:
            raise self.err(f"'{where}': {fn}() takes a dimensionless argument, got "
                           f"{describe_dims(d)}")
        try:
            if fn == "exp":
                return math.exp(v), NONE
            if v <= 0:
                raise self.err(f"'{where}': log of {v:g}")
            return math.log(v), NONE
        except OverflowError:
            raise self.err(f"'{where}' overflows") from None


def evaluate(text: str, values: Mapping[str, tuple[float, str]], result_unit: str) -> Derivation:
    """The formula's value in result_unit, with its inputs; FormulaError when it is not
    allowed, names an unknown value, has a dimension other than result_unit's, or is not a
    finite number."""
    tree = parse(text)
    try:
        scale, want = unit_si(result_unit)
    except UnitError as exc:
        raise FormulaError(str(exc)) from None
    ev = _Eval(text.strip(), values)
    try:
        value, dims = ev(tree.body)
    except (ZeroDivisionError, OverflowError) as exc:
        raise ev.err(str(exc)) from None
    except RecursionError:
        raise ev.err("is nested too deeply") from None
    if dims != want:
        raise ev.err(f"gives {describe_dims(dims)}, which is not {result_unit} "
                     f"({describe_dims(want)})")
    value /= scale
    if math.isfinite(value):
        value = float(f"{value:.12g}")      # 1500 rpm -> rad/s -> rpm is 1500, not 1500.0000000000002
    if not math.isfinite(value):
        raise ev.err(f"is not a finite number ({value})")
    return Derivation(text.strip(), float(value), result_unit, tuple(ev.inputs.values()))


__all__ = ["FormulaError", "Derivation", "Input", "evaluate", "parse", "names_in", "unit_si",
           "FUNCTIONS", "DIMENSIONS"]
