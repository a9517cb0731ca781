"""What `hil run` pays at start-up for its own classes: each dataclass is built when its module
is imported, and a dataclass without a docstring of its own gets one made from
inspect.signature (~0.2 ms each here); the protocol's message classes have one __init__
compiled, not two."""
from __future__ import annotations

import dataclasses
import importlib

import pytest

from protocol import messages

# The modules of a `hil run` that this rule covers (hil.session and hil.links are not).
MODULES = ("hil.plans.checks", "hil.plans.format", "hil.plans.limits", "hil.plans.outcome",
           "hil.plans.signals", "hil.plans.units", "hil.run.console", "hil.run.runner",
           "hil.faults.injector", "plant_rt.profile", "plant_rt.sensors", "protocol.messages")


@pytest.mark.parametrize("module", MODULES)
def test_every_dataclass_has_a_docstring_of_its_own(module):
    mod = importlib.import_module(module)
    generated = [name for name, obj in vars(mod).items()
                 if isinstance(obj, type) and dataclasses.is_dataclass(obj)
                 and obj.__module__ == module
                 and (obj.__doc__ or "").startswith(obj.__name__ + "(")]
    assert not generated, f"{module}: dataclasses without a docstring: {generated}"


def test_message_classes_get_one_init_that_stores_through_the_slots():
    fast = [cls for cls in messages.MESSAGE_CLASSES.values()
            if dataclasses.fields(cls) and cls is not messages.Hello]
    assert len(fast) == 13
    for cls in fast:
        assert cls.__dataclass_params__.init is False          # no generated __init__ compiled
        assert cls.__init__.__qualname__ == f"{cls.__name__}.__init__"
        names = [f.name for f in dataclasses.fields(cls)]
        values = list(range(1, len(names) + 1))
        msg = cls(*values)
        assert msg == cls(**dict(zip(names, values))) and hash(msg) == hash(cls(*values))
        assert [getattr(msg, n) for n in names] == values
        assert repr(msg).startswith(f"{cls.__name__}({names[0]}=1")
        assert dataclasses.replace(msg, **{names[0]: 99}) == cls(99, *values[1:])
        with pytest.raises(dataclasses.FrozenInstanceError):
            setattr(msg, names[0], 5)
    with pytest.raises(TypeError):
        messages.Sample(1, 2, 3)
    assert messages.Hello(1, 0, 0, 50_000, name="stub").name_len == 4   # __post_init__ kept
