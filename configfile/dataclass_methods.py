"""Dataclasses whose methods are closures instead of code compiled for each class.

Python 3.11's dataclasses compile each generated method from source text (__init__, __repr__,
__eq__, and a frozen class's __hash__, __setattr__ and __delattr__: ~0.2 ms each here), and
`hil run` imports some sixty dataclasses at start-up (the plan format, the protocol's messages,
the plant's parameters, ...). `dataclass` here takes the standard decorator's arguments (not
order or unsafe_hash; nor InitVar fields or fields left out of __init__) and lets the
standard one find the fields, their defaults, the match args and the slots, with nothing to
generate; then it adds methods that behave as the generated ones do:

- __repr__, __eq__ and __hash__ are closures over the field names: the same text (recursion
  shown as ...), == on the tuples of the compared fields of two instances of the same class,
  hash of the hashed fields' tuple for a frozen class and no hash for a mutable one;
- a frozen class's __setattr__ and __delattr__ are closures raising FrozenInstanceError for
  the same names, and with slots it gets the same __getstate__/__setstate__ for pickling;
- __init__ has the generated one's parameters (names, order, defaults, `*` before the
  keyword-only ones, annotations), on one small code object per count of parameters, compiled
  once and renamed for each class (CodeType.replace); its body hands the arguments to a
  closure that stores them in the fields' order (object.__setattr__ when frozen), calling a
  default factory for an argument not given, then calls __post_init__.

What that loop costs: making an instance takes ~3,000 instructions more than with the
generated __init__ for a frozen class of a few fields, ~1,000 more per field for a mutable
one (setattr against a compiled store). None of these classes is made per control period:
the per-period messages (SAMPLE, GATES, ...) have their own __init__ (protocol/messages.py).

__dataclass_params__ says what was asked. tests/test_dataclass_methods.py holds the two
decorators to the same results.
"""
from __future__ import annotations

import dataclasses
import sys
import types
from operator import attrgetter
from reprlib import recursive_repr


class _Factory:
    """The default of a parameter whose field has a default factory (shown as <factory>)."""

    def __repr__(self):
        return "<factory>"


_FACTORY = _Factory()


def _tuple_of(names: tuple[str, ...]):
    """A function giving an instance's fields `names` as a tuple."""
    if len(names) > 1:
        return attrgetter(*names)
    if names:
        name = names[0]
        return lambda self: (getattr(self, name),)
    return lambda self: ()


def _standard(cls, frozen: bool, kwargs: dict):
    """The standard decorator with nothing to generate: the fields, __dataclass_fields__, match
    args, slots. It is told frozen=False, so for the length of the call a frozen base's
    parameters read frozen=False too (else it would refuse the base); the inheritance rule it
    then does not check is checked here, after it, as it would have been."""
    frozen_bases = list({id(p): p for b in cls.__mro__[1:]
                         if getattr(b, "__dataclass_fields__", None) is not None
                         and (p := getattr(b, "__dataclass_params__")).frozen}.values())
    for params in frozen_bases:
        params.frozen = False
    try:
        cls = dataclasses.dataclass(cls, init=False, repr=False, eq=False, frozen=False, **kwargs)
    finally:
        for params in frozen_bases:
            params.frozen = True
    if any(getattr(b, "__dataclass_fields__", None) is not None for b in cls.__mro__[1:]):
        if frozen_bases and not frozen:
            raise TypeError("cannot inherit non-frozen dataclass from a frozen one")
        if not frozen_bases and frozen:
            raise TypeError("cannot inherit frozen dataclass from a non-frozen one")
    return cls


_INIT_CODES: dict[tuple, types.CodeType] = {}


def _init_code(positional: int, keyword: int, order: tuple[int, ...]) -> types.CodeType:
    """`def __init__(self, _0, .., *, _k, ..): _store(self, (arguments in `order`))`, compiled
    once for each count of parameters; `_store` is the function's one closure cell."""
    key = (positional, keyword, order)
    code = _INIT_CODES.get(key)
    if code is None:
        names = [f"_{i}" for i in range(positional + keyword)]
        params = ["self", *names[:positional], *(["*", *names[positional:]] if keyword else [])]
        args = "".join(f"{names[i]}, " for i in order)
        src = (f"def _make(_store):\n def __init__({', '.join(params)}):\n"
               f"  _store(self, ({args}))\n return __init__\n")
        namespace: dict = {}
        exec(compile(src, "<dataclass __init__>", "exec"), namespace)  # noqa: S102 - fixed text
        code = next(c for c in namespace["_make"].__code__.co_consts if isinstance(c, types.CodeType))
        _INIT_CODES[key] = code
    return code


def _init(cls, frozen: bool):
    """The __init__ the standard decorator would give `cls`, without compiling it."""
    fields = dataclasses.fields(cls)
    unsupported = [f.name for f in cls.__dataclass_fields__.values()
                   if f._field_type is dataclasses._FIELD_INITVAR] + [f.name for f in fields if not f.init]
    if unsupported:
        raise TypeError(f"{cls.__qualname__}: InitVar and init=False fields ({', '.join(unsupported)}) "
                        "are not supported: use dataclasses.dataclass")
    in_order = [f for f in fields if not f.kw_only] + [f for f in fields if f.kw_only]
    seen_default = False
    for f in in_order:
        if f.kw_only:
            break
        if f.default is not dataclasses.MISSING or f.default_factory is not dataclasses.MISSING:
            seen_default = True
        elif seen_default:
            raise TypeError(f"non-default argument {f.name!r} follows default argument")

    def default(f):
        return _FACTORY if f.default_factory is not dataclasses.MISSING else f.default

    positional = [f for f in in_order if not f.kw_only]
    defaults = tuple(default(f) for f in positional if default(f) is not dataclasses.MISSING)
    kwdefaults = {f.name: default(f) for f in in_order if f.kw_only and default(f) is not dataclasses.MISSING}
    names = tuple(f.name for f in fields)
    factories = tuple(f.default_factory if f.default_factory is not dataclasses.MISSING else None
                      for f in fields)
    set_field = object.__setattr__ if frozen else setattr
    post_init = hasattr(cls, "__post_init__")

    if any(factories):
        def store(self, values):
            for name, value, factory in zip(names, values, factories):
                set_field(self, name, factory() if value is _FACTORY and factory else value)
            if post_init:
                self.__post_init__()
    elif post_init:
        def store(self, values):
            for name, value in zip(names, values):
                set_field(self, name, value)
            self.__post_init__()
    else:
        def store(self, values):
            for name, value in zip(names, values):
                set_field(self, name, value)

    code = _init_code(len(positional), len(in_order) - len(positional),
                      tuple(in_order.index(f) for f in fields))
    self_name = "__dataclass_self__" if "self" in cls.__dataclass_fields__ else "self"
    code = code.replace(co_varnames=(self_name, *(f.name for f in in_order)),
                        co_qualname=f"{cls.__qualname__}.__init__")
    module = sys.modules.get(cls.__module__)
    init = types.FunctionType(code, module.__dict__ if module else {}, "__init__", defaults or None,
                              (types.CellType(store),))
    init.__kwdefaults__ = kwdefaults or None
    init.__annotations__ = {**{f.name: f.type for f in in_order}, "return": None}
    init.__qualname__ = f"{cls.__qualname__}.__init__"
    return init


def _named(cls, method):
    """`method` named as the class's own (its __qualname__ is what tracebacks and help show)."""
    method.__qualname__ = f"{cls.__qualname__}.{method.__name__}"
    return method


def _frozen_methods(cls, declared):
    """__setattr__ and __delattr__ refusing the fields, as the generated ones do: they test
    for and call super() on the class as declared, which with slots=True is not `cls` (the
    standard decorator makes them before it remakes the class with slots)."""
    names = frozenset(f.name for f in dataclasses.fields(cls))
    error = dataclasses.FrozenInstanceError

    def __setattr__(self, name, value):
        if type(self) is declared or name in names:
            raise error(f"cannot assign to field {name!r}")
        super(declared, self).__setattr__(name, value)

    def __delattr__(self, name):
        if type(self) is declared or name in names:
            raise error(f"cannot delete field {name!r}")
        super(declared, self).__delattr__(name)

    return {"__setattr__": _named(cls, __setattr__), "__delattr__": _named(cls, __delattr__)}


def _getstate(self):
    """A frozen class with slots pickles its fields' values (as dataclasses' own function)."""
    return [getattr(self, f.name) for f in dataclasses.fields(self)]


def _setstate(self, state):
    """... and unpickles them past its __setattr__."""
    for f, value in zip(dataclasses.fields(self), state):
        object.__setattr__(self, f.name, value)


def dataclass(cls=None, /, *, init: bool = True, repr: bool = True, eq: bool = True,
              frozen: bool = False, **kwargs):
    """dataclasses.dataclass with the same arguments, but no method compiled for the class."""
    if kwargs.get("order") or kwargs.get("unsafe_hash"):
        raise TypeError("configfile.dataclass_methods.dataclass: order and unsafe_hash are not supported")

    def wrap(cls):
        own = [name for name in ("__repr__", "__eq__", "__hash__") if name in cls.__dict__]
        if own:
            raise TypeError(f"{cls.__qualname__} defines {', '.join(own)}: use dataclasses.dataclass")
        if frozen:
            for name in ("__setattr__", "__delattr__"):
                if name in cls.__dict__:
                    raise TypeError(f"Cannot overwrite attribute {name} in class {cls.__name__}")
        needs_doc = not getattr(cls, "__doc__")
        if needs_doc:
            cls.__doc__ = "-"          # made below, from the signature of our __init__
        declared = cls
        cls = _standard(cls, frozen, kwargs)
        params = cls.__dataclass_params__
        params.init, params.repr, params.eq, params.frozen = init, repr, eq, frozen
        fields = dataclasses.fields(cls)
        methods = {}
        if init and "__init__" not in cls.__dict__:
            methods["__init__"] = _init(cls, frozen)
        if repr:
            shown = tuple(f.name for f in fields if f.repr)

            def __repr__(self):
                return (self.__class__.__qualname__ + "("
                        + ", ".join([f"{name}={getattr(self, name)!r}" for name in shown]) + ")")

            methods["__repr__"] = _named(cls, recursive_repr()(__repr__))
        if eq:
            compared = _tuple_of(tuple(f.name for f in fields if f.compare))

            def __eq__(self, other):
                if other.__class__ is self.__class__:
                    return compared(self) == compared(other)
                return NotImplemented

            methods["__eq__"] = _named(cls, __eq__)
            methods["__hash__"] = None
        if frozen:
            methods.update(_frozen_methods(cls, declared))
            if eq:
                hashed = _tuple_of(tuple(f.name for f in fields
                                         if (f.compare if f.hash is None else f.hash)))

                def __hash__(self):
                    return hash(hashed(self))

                methods["__hash__"] = _named(cls, __hash__)
            if kwargs.get("slots"):
                for name, method in (("__getstate__", _getstate), ("__setstate__", _setstate)):
                    if name not in cls.__dict__:
                        methods[name] = method
        for name, method in methods.items():
            setattr(cls, name, method)
        if needs_doc:
            import inspect
            try:
                text_sig = str(inspect.signature(cls)).replace(" -> None", "")
            except (TypeError, ValueError):
                text_sig = ""
            cls.__doc__ = cls.__name__ + text_sig
        return cls

    return wrap if cls is None else wrap(cls)
