"""configfile.dataclass_methods.dataclass gives the results of the standard dataclass: the same
repr (recursion included), ==, hash (or none), frozen-ness, fields, replace and match args,
for every shape of class declared with it and for each class of the modules that use it."""
from __future__ import annotations

import dataclasses
import importlib
import math
from typing import ClassVar

import pytest

from configfile import dataclass_methods
from configfile.dataclass_methods import dataclass as lean

MODULES = ("hil.plans.checks", "hil.plans.format", "hil.plans.limits", "hil.plans.outcome",
           "hil.plans.signals", "hil.plans.units", "hil.session.policy", "protocol.messages",
           "configfile.source", "hil.faults.injector", "hil.links.registry", "hil.run.console",
           "hil.run.runner")


def _pair(namespace: dict, bases: tuple = (), **kwargs):
    """The same class body made twice: by the standard decorator and by ours."""
    def make(decorator):
        ns = dict(namespace)
        ns["__qualname__"] = "Twin"
        return decorator(type("Twin", bases[decorator is lean] if bases else (), ns), **kwargs)
    return make(dataclasses.dataclass), make(lean)


def _same(std, ours, *args, **kwargs):
    a, b = std(*args, **kwargs), ours(*args, **kwargs)
    assert (std.__repr__ is object.__repr__) == (ours.__repr__ is object.__repr__)
    if std.__repr__ is not object.__repr__:
        assert repr(a) == repr(b)
    assert (a == std(*args, **kwargs)) == (b == ours(*args, **kwargs))
    assert (a != std(*args, **kwargs)) == (b != ours(*args, **kwargs))
    assert (a == object()) == (b == object())
    assert type(std).__name__ == type(ours).__name__
    assert (std.__hash__ is None) == (ours.__hash__ is None)
    assert (std.__hash__ is object.__hash__) == (ours.__hash__ is object.__hash__)
    if std.__hash__ not in (None, object.__hash__):
        assert hash(a) == hash(b)
    assert [f.name for f in dataclasses.fields(a)] == [f.name for f in dataclasses.fields(b)]
    assert getattr(std, "__match_args__", None) == getattr(ours, "__match_args__", None)
    return a, b


SHAPES = {
    "no fields": ({"__annotations__": {}}, {}),
    "one field": ({"__annotations__": {"x": "float"}}, {}),
    "defaults": ({"__annotations__": {"x": "int", "y": "str", "z": "tuple"}, "y": "a", "z": (1, 2)}, {}),
    "factory": ({"__annotations__": {"x": "int", "d": "tuple"},
                 "d": dataclasses.field(default_factory=tuple)}, {}),
    "classvar": ({"__annotations__": {"kind": ClassVar[str], "x": "int"}, "kind": "k"}, {}),
    "repr/compare/hash off": ({"__annotations__": {"x": "int", "y": "int", "z": "int"},
                               "y": dataclasses.field(default=0, repr=False),
                               "z": dataclasses.field(default=0, compare=False, hash=True)}, {}),
}
FLAGS = [{}, {"frozen": True}, {"frozen": True, "kw_only": True}, {"eq": False}, {"repr": False},
         {"frozen": True, "slots": True}, {"frozen": True, "eq": False}]


@pytest.mark.parametrize("flags", FLAGS, ids=str)
@pytest.mark.parametrize("shape", SHAPES)
def test_same_results_as_the_standard_decorator(shape, flags):
    namespace, _ = SHAPES[shape]
    std, ours = _pair(namespace, **flags)
    names = [f.name for f in dataclasses.fields(std) if f.init]
    values = {n: v for n, v in zip(names, (3, "b", (4,)))}
    a, b = _same(std, ours, **values)
    if flags.get("frozen"):
        for obj in (a, b):
            for name in names:
                with pytest.raises(dataclasses.FrozenInstanceError):
                    setattr(obj, name, 1)
                with pytest.raises(dataclasses.FrozenInstanceError):
                    delattr(obj, name)
    if names and flags.get("repr", True):
        assert repr(dataclasses.replace(a, **{names[0]: 7})) == repr(dataclasses.replace(b, **{names[0]: 7}))


def test_nan_fields_compare_as_tuples_do_and_hashes_match():
    std, ours = _pair({"__annotations__": {"x": "float"}}, frozen=True)
    nan = math.nan
    assert (std(nan) == std(nan)) == (ours(nan) == ours(nan)) is True    # the same object
    assert (std(nan) == std(float("nan"))) == (ours(nan) == ours(float("nan"))) is False
    assert hash(std(1.5)) == hash(ours(1.5)) == hash((1.5,))


def test_recursive_repr_and_subclasses():
    std, ours = _pair({"__annotations__": {"x": "object"}})
    a, b = std(None), ours(None)
    a.x, b.x = a, b
    assert repr(a) == repr(b) == "Twin(x=...)"

    bases = ((std,), (ours,))
    std_sub, ours_sub = _pair({"__annotations__": {"y": "int"}, "y": 0}, bases)
    _same(std_sub, ours_sub, 1, y=2)
    assert std_sub(1) != std(1) and ours_sub(1) != ours(1)      # other class: not equal


def test_what_it_does_not_take():
    with pytest.raises(TypeError):
        lean(order=True)
    with pytest.raises(TypeError):
        lean(type("A", (), {"__annotations__": {}, "__eq__": lambda s, o: True}))


def _classes():
    for module in MODULES:
        mod = importlib.import_module(module)
        for obj in vars(mod).values():
            if isinstance(obj, type) and obj.__module__ == module and dataclasses.is_dataclass(obj):
                yield obj


def test_every_dataclass_of_those_modules_is_made_by_it():
    classes = list(_classes())
    assert len(classes) >= 48
    generated = [c.__qualname__ for c in classes
                 if c.__dataclass_params__.repr or c.__dataclass_params__.eq]
    assert not generated, f"compiled by the standard decorator: {generated}"


@pytest.mark.parametrize("cls", list(_classes()), ids=lambda c: c.__qualname__)
def test_each_class_behaves_as_the_standard_decorator_would_make_it(cls):
    """A twin of each class from the standard decorator (same fields, same flags) gives the
    same repr, == and hash for the same field values."""
    fields = dataclasses.fields(cls)
    frozen = cls.__dataclass_params__.frozen
    eq = "__eq__" in cls.__dict__
    twin = dataclasses.make_dataclass(
        cls.__name__, [(f.name, f.type, dataclasses.field(repr=f.repr, compare=f.compare, hash=f.hash))
                       for f in fields], frozen=frozen, eq=eq)
    twin.__qualname__ = cls.__qualname__

    def instance(kind, values):
        obj = object.__new__(kind)
        for name, value in values.items():
            object.__setattr__(obj, name, value)
        return obj

    values = {f.name: (i, f"v{i}") for i, f in enumerate(fields)}
    a, b = instance(cls, values), instance(twin, values)
    assert repr(a) == repr(b)
    assert (a == instance(cls, values)) == (b == instance(twin, values))
    assert (cls.__hash__ is None) == (twin.__hash__ is None)
    if twin.__hash__ is not None and eq:
        assert hash(a) == hash(b)
    assert cls.__repr__.__qualname__ == f"{cls.__qualname__}.__repr__"
    assert dataclass_methods.dataclass is lean
