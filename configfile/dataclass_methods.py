"""Dataclasses with __repr__, __eq__ and __hash__ made as closures instead of compiled for
each class.

Python 3.11's dataclasses compile each generated method from source text: six for a frozen
class, ~3.1 M instructions, and `hil run` imports some sixty dataclasses (the plan format,
the protocol's messages, ...). `dataclass` here is the standard decorator (same arguments;
order and unsafe_hash are not taken) that leaves repr and eq to closures over the field
names, which behave as the generated methods do: the same text (recursion shown as ...),
== on the tuples of the compared fields of two instances of the same class, hash of the
hashed fields' tuple for a frozen class and no hash for a mutable one. __init__, and a frozen
class's __setattr__ and __delattr__, are the standard ones. Only __dataclass_params__ tells
the difference (its repr and eq are False). tests/test_dataclass_methods.py holds the two to
the same results.
"""
from __future__ import annotations

import dataclasses
from operator import attrgetter
from reprlib import recursive_repr


def _tuple_of(names: tuple[str, ...]):
    """A function giving an instance's fields `names` as a tuple."""
    if len(names) > 1:
        return attrgetter(*names)
    if names:
        name = names[0]
        return lambda self: (getattr(self, name),)
    return lambda self: ()


def dataclass(cls=None, /, *, repr: bool = True, eq: bool = True, **kwargs):
    """dataclasses.dataclass with the same arguments, but no compiled __repr__/__eq__/__hash__."""
    if kwargs.get("order") or kwargs.get("unsafe_hash"):
        raise TypeError("configfile.dataclass_methods.dataclass: order and unsafe_hash are not supported")

    def wrap(cls):
        own = [name for name in ("__repr__", "__eq__", "__hash__") if name in cls.__dict__]
        if own:
            raise TypeError(f"{cls.__qualname__} defines {', '.join(own)}: use dataclasses.dataclass")
        cls = dataclasses.dataclass(cls, repr=False, eq=False, **kwargs)
        fields = dataclasses.fields(cls)
        methods = {}
        if repr:
            shown = tuple(f.name for f in fields if f.repr)

            def __repr__(self):
                return (self.__class__.__qualname__ + "("
                        + ", ".join([f"{name}={getattr(self, name)!r}" for name in shown]) + ")")

            methods["__repr__"] = recursive_repr()(__repr__)
        if eq:
            compared = _tuple_of(tuple(f.name for f in fields if f.compare))

            def __eq__(self, other):
                if other.__class__ is self.__class__:
                    return compared(self) == compared(other)
                return NotImplemented

            methods["__eq__"] = __eq__
            methods["__hash__"] = None
            if kwargs.get("frozen"):
                hashed = _tuple_of(tuple(f.name for f in fields
                                         if (f.compare if f.hash is None else f.hash)))

                def __hash__(self):
                    return hash(hashed(self))

                methods["__hash__"] = __hash__
        for name, method in methods.items():
            if method is not None:
                method.__qualname__ = f"{cls.__qualname__}.{name}"
            setattr(cls, name, method)
        return cls

    return wrap if cls is None else wrap(cls)
