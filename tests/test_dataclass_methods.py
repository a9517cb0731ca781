"""configfile.dataclass_methods.dataclass gives the results of the standard dataclass: the same
__init__ (signature, defaults, factories, __post_init__, the errors of a bad call), repr
(recursion included), ==, hash (or none), frozen-ness, fields, replace, match args, pickling
and class docstring, for every shape of class declared with it and for each class of the
modules that use it; and none of those classes has a method compiled by the standard one."""
from __future__ import annotations

import copy
import dataclasses
import importlib
import inspect
import math
from typing import ClassVar

import pytest

from configfile import dataclass_methods
from configfile.dataclass_methods import dataclass as lean

MODULES = ("hil.plans.checks", "hil.plans.format", "hil.plans.limits", "hil.plans.outcome",
           "hil.plans.signals", "hil.plans.units", "hil.session.policy", "protocol.messages",
           "configfile.source", "hil.faults.injector", "hil.links.registry", "hil.run.console",
           "hil.run.runner", "plant_rt.dc_link", "plant_rt.inverter", "plant_rt.load",
           "plant_rt.motor", "plant_rt.sensors", "plant_rt.profile", "hil.session.link_tap",
           "hil.session.bench_session")


def _pair(namespace: dict, bases: tuple = (), **kwargs):
    """The same class body made twice: by the standard decorator and by ours."""
    def make(decorator):
        ns = dict(namespace)
        ns["__qualname__"] = "Twin"
        return decorator(type("Twin", bases[decorator is lean] if bases else (), ns), **kwargs)
    return make(dataclasses.dataclass), make(lean)


def _init_errors(cls, names):
    """The TypeError of each kind of bad call of cls(...) as text (None: no error)."""
    calls = [((), {}), (tuple(range(len(names) + 1)), {}), ((1,), {"nope": 1})]
    calls += [((1,), {names[0]: 1})] if names else []
    messages = []
    for args, kwargs in calls:
        try:
            cls(*args, **kwargs)
            messages.append(None)
        except TypeError as error:
            messages.append(str(error))
    assert any(messages)
    return messages


def _same_init(std, ours):
    """The same __init__ as far as a caller or a reader can tell."""
    assert str(inspect.signature(std)) == str(inspect.signature(ours))
    assert str(inspect.signature(std.__init__)) == str(inspect.signature(ours.__init__))
    for name in ("__qualname__", "__name__", "__module__", "__defaults__", "__kwdefaults__",
                 "__annotations__", "__doc__"):
        assert repr(getattr(std.__init__, name)) == repr(getattr(ours.__init__, name)), name
    assert std.__doc__ == ours.__doc__
    std_params = std.__dataclass_params__
    ours_params = ours.__dataclass_params__
    assert all(getattr(std_params, name) == getattr(ours_params, name) for name in std_params.__slots__)
    names = [f.name for f in dataclasses.fields(std) if f.init]
    assert _init_errors(std, names) == _init_errors(ours, names)


def _same(std, ours, *args, **kwargs):
    _same_init(std, ours)
    a, b = std(*args, **kwargs), ours(*args, **kwargs)
    assert list(vars(a) if hasattr(a, "__dict__") else ()) == list(vars(b) if hasattr(b, "__dict__") else ())
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
    "keyword-only field first": ({"__annotations__": {"k": "int", "x": "int", "y": "list"},
                                  "k": dataclasses.field(default=5, kw_only=True),
                                  "y": dataclasses.field(default_factory=list)}, {}),
    "a field named self": ({"__annotations__": {"self": "int", "x": "int"}, "x": 2}, {}),
    "__post_init__": ({"__annotations__": {"x": "int", "y": "int"}, "y": 0,
                       "__post_init__": lambda self: object.__setattr__(self, "y", self.x * 2)}, {}),
    "docstring": ({"__annotations__": {"x": "int"}, "__doc__": "Its own."}, {}),
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
        raised = []
        for obj in (a, b):                      # with slots, a TypeError from super() in both
            with pytest.raises((AttributeError, TypeError)) as error:
                obj.other = 1
            raised.append(type(error.value))
        assert raised[0] is raised[1]
    if names and flags.get("repr", True):
        assert repr(dataclasses.replace(a, **{names[0]: 7})) == repr(dataclasses.replace(b, **{names[0]: 7}))
    if flags.get("slots"):
        assert a.__getstate__() == b.__getstate__()
        assert repr(copy.copy(a)) == repr(copy.copy(b))        # through __getstate__/__setstate__
        assert "__setstate__" in vars(std) and "__setstate__" in vars(ours)


def test_each_instance_gets_its_own_default_from_the_factory():
    std, ours = _pair(SHAPES["keyword-only field first"][0])
    for cls in (std, ours):
        a, b = cls(1), cls(1)
        assert a.y == [] and a.y is not b.y
        assert cls(1, [3]).y == [3]


def test_frozen_bases_and_subclasses_mixed_with_the_standard_decorator():
    """Our frozen class under a standard frozen subclass and the other way round; the
    inheritance rules refuse the same classes with the same messages."""
    body = {"__annotations__": {"x": "int"}}
    for base_maker, sub_maker in ((lean, dataclasses.dataclass), (dataclasses.dataclass, lean),
                                  (lean, lean)):
        base = base_maker(type("Base", (), dict(body)), frozen=True)
        sub = sub_maker(type("Sub", (base,), {"__annotations__": {"y": "int"}, "y": 1}), frozen=True)
        assert sub(3).y == 1 and sub.__dataclass_params__.frozen and base.__dataclass_params__.frozen
        with pytest.raises(dataclasses.FrozenInstanceError):
            sub(3).x = 4
        plain_sub = type("Plain", (base,), {})          # not a dataclass: may set other names
        obj = plain_sub(3)
        obj.other = 1
        assert obj.other == 1
        for frozen, message in ((False, "cannot inherit non-frozen dataclass from a frozen one"),):
            with pytest.raises(TypeError, match=message):
                sub_maker(type("Bad", (base,), {"__annotations__": {}}), frozen=frozen)
    for maker in (lean, dataclasses.dataclass):
        mutable = maker(type("Mutable", (), dict(body)))
        with pytest.raises(TypeError, match="cannot inherit frozen dataclass from a non-frozen one"):
            lean(type("Bad", (mutable,), {"__annotations__": {}}), frozen=True)


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
    with pytest.raises(TypeError, match="InitVar"):
        lean(type("A", (), {"__annotations__": {"x": dataclasses.InitVar[int]}}))
    with pytest.raises(TypeError, match="init=False"):
        lean(type("A", (), {"__annotations__": {"x": "int"}, "x": dataclasses.field(init=False)}))
    with pytest.raises(TypeError, match="non-default argument 'y' follows default argument"):
        lean(type("A", (), {"__annotations__": {"x": "int", "y": "int"}, "x": 0}))
    with pytest.raises(TypeError, match="Cannot overwrite attribute __setattr__ in class A"):
        lean(type("A", (), {"__annotations__": {}, "__setattr__": object.__setattr__}), frozen=True)


def test_a_class_with_its_own_init_keeps_it():
    def __init__(self):
        object.__setattr__(self, "x", 9)

    for maker in (lean, dataclasses.dataclass):
        cls = maker(type("A", (), {"__annotations__": {"x": "int"}, "__init__": __init__}), frozen=True)
        assert cls.__init__ is __init__ and cls().x == 9


def _classes():
    for module in MODULES:
        mod = importlib.import_module(module)
        for obj in vars(mod).values():
            if isinstance(obj, type) and obj.__module__ == module and dataclasses.is_dataclass(obj):
                yield obj


def _compiled_by_the_standard_decorator(cls):
    """The methods of cls that dataclasses compiled (they are made inside its __create_fn__)."""
    codes = {name: getattr(inspect.unwrap(value), "__code__", None) for name, value in vars(cls).items()
             if callable(value)}
    return [name for name, code in codes.items() if code and code.co_qualname.startswith("__create_fn__")]


def test_the_check_for_compiled_methods_sees_them():
    std, _ = _pair({"__annotations__": {"x": "int"}}, frozen=True)
    assert sorted(_compiled_by_the_standard_decorator(std)) == [
        "__delattr__", "__eq__", "__hash__", "__init__", "__repr__", "__setattr__"]


def test_every_dataclass_of_those_modules_is_made_by_it():
    classes = list(_classes())
    assert len(classes) >= 60
    generated = {c.__qualname__: _compiled_by_the_standard_decorator(c) for c in classes}
    assert not {name: methods for name, methods in generated.items() if methods}


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
    if cls.__dataclass_params__.init:
        init_twin = dataclasses.make_dataclass(
            cls.__name__, [(f.name, f.type, dataclasses.field(
                default=f.default, default_factory=f.default_factory, kw_only=f.kw_only))
                for f in fields], frozen=frozen)
        assert str(inspect.signature(cls)) == str(inspect.signature(init_twin))
    assert repr(a) == repr(b)
    assert (a == instance(cls, values)) == (b == instance(twin, values))
    assert (cls.__hash__ is None) == (twin.__hash__ is None)
    if twin.__hash__ is not None and eq:
        assert hash(a) == hash(b)
    assert cls.__repr__.__qualname__ == f"{cls.__qualname__}.__repr__"
    assert dataclass_methods.dataclass is lean
