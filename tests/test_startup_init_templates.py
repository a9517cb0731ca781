"""configfile/init_templates.py: the __init__ code objects that configfile.dataclass_methods
and protocol.messages would otherwise compile at import (one compile() is ~0.9 M instructions;
`hil run` made 31 of them at start-up). The file is the text `template_source` gives (so it
cannot drift from what the users expect of it); a count of parameters beyond it is still
compiled, and gives the same __init__ as one taken from the file."""
from __future__ import annotations

import dataclasses
import dis
import inspect
import pickle
import subprocess
import sys
from pathlib import Path

import pytest

from configfile import dataclass_methods, init_templates
from configfile.dataclass_methods import dataclass as lean

ROOT = Path(__file__).resolve().parents[1]

HEADER = '''"""The __init__ code objects of configfile.dataclass_methods and protocol.messages, compiled
once into this module's .pyc instead of at every start-up (compile() costs ~0.9 M instructions
a function, ~4 % of a short `hil run` for the 31 it made). Each is renamed for its class with
CodeType.replace (parameter names, counts, file and line as the compiled one had). Generated:
tests/test_startup_init_templates.py holds it to `template_source()`; do not edit by hand.

store_N: dataclass_methods' `__init__(self, _0, .., _N-1): _store(self, (_0, .., ))`, the one
closure cell `_store` storing the values (a keyword-only tail: co_kwonlyargcount).
slots_N: protocol.messages' `__init__(self, _0, .., _N-1)` calling the global `_sK(self, _K)`
for each field (the slot descriptors' __set__, renamed `_set_<field>`).

The future import gives the code the flags of the callers' compile() and exec(), which inherit it.
"""
from __future__ import annotations
'''
MAX = 24


def template_source(max_params: int = MAX) -> str:
    parts = [HEADER, f"\nMAX_PARAMS = {max_params}\n"]
    for n in range(max_params + 1):
        params = "".join(f", _{i}" for i in range(n))
        values = "".join(f"_{i}, " for i in range(n))
        parts.append(f"\n\ndef store_{n}(_store):\n    def __init__(self{params}):\n"
                     f"        _store(self, ({values}))\n    return __init__\n")
    for n in range(1, max_params + 1):
        params = "".join(f", _{i}" for i in range(n))
        body = "".join(f"    _s{i}(self, _{i})\n" for i in range(n))
        parts.append(f"\n\ndef slots_{n}(self{params}):\n{body}")
    return "".join(parts)


def test_the_file_is_the_generated_text():
    assert (ROOT / "configfile" / "init_templates.py").read_text() == template_source()


def _bytecode(code):
    return [(i.opname, i.argval) for i in dis.get_instructions(code)]


@pytest.mark.parametrize("positional,keyword", [(0, 0), (1, 0), (3, 0), (0, 2), (2, 3), (MAX, 0),
                                                (0, MAX), (MAX + 1, 0), (3, MAX)])
def test_a_template_is_the_code_compile_would_give(positional, keyword, monkeypatch):
    n = positional + keyword
    order = tuple(range(n))
    from_file = dataclass_methods._init_code(positional, keyword, order)
    monkeypatch.setattr(dataclass_methods, "_INIT_CODES", {})
    monkeypatch.setattr(init_templates, "MAX_PARAMS", -1)      # every count compiled
    compiled = dataclass_methods._init_code(positional, keyword, order)
    assert _bytecode(from_file) == _bytecode(compiled)
    for name in ("co_argcount", "co_kwonlyargcount", "co_posonlyargcount", "co_varnames",
                 "co_freevars", "co_filename", "co_firstlineno", "co_name", "co_flags", "co_nlocals"):
        assert getattr(from_file, name) == getattr(compiled, name), name
    assert list(from_file.co_lines()) == list(compiled.co_lines())


def test_keyword_only_fields_before_positional_ones_are_compiled_in_their_order():
    @lean(frozen=True)
    class Mixed:
        k: int = dataclasses.field(default=5, kw_only=True)
        x: int = 0
        y: tuple = ()

    @dataclasses.dataclass(frozen=True)
    class Standard:
        k: int = dataclasses.field(default=5, kw_only=True)
        x: int = 0
        y: tuple = ()

    assert str(inspect.signature(Mixed)) == str(inspect.signature(Standard)) == "(x: 'int' = 0, y: 'tuple' = (), *, k: 'int' = 5) -> None"
    assert repr(Mixed(1, (2,), k=3)) == "test_keyword_only_fields_before_positional_ones_are_compiled_in_their_order.<locals>.Mixed(k=3, x=1, y=(2,))"


@pytest.mark.parametrize("count", [1, 2, 17, MAX, MAX + 1])
def test_a_slot_init_from_the_file_is_the_one_exec_would_give(count):
    names = [f"f{i}" for i in range(count)]

    def make():
        return dataclass_methods.dataclass(type("M", (), {"__annotations__": dict.fromkeys(names, "int")}),
                                           frozen=True, slots=True, init=False)

    fast = dataclass_methods.slots_init(make())
    # What protocol.messages compiled before (its _fast_init, up to e532cd7).
    slow = make()
    namespace = {f"_set_{n}": slow.__dict__[n].__set__ for n in names}
    src = f"def __init__(self, {', '.join(names)}):\n" + "".join(f"    _set_{n}(self, {n})\n" for n in names)
    exec(src, namespace)
    reference = namespace["__init__"]
    assert _bytecode(fast.__init__.__code__) == _bytecode(reference.__code__)
    for name in ("co_argcount", "co_kwonlyargcount", "co_varnames", "co_names", "co_filename",
                 "co_firstlineno", "co_name", "co_flags", "co_nlocals"):
        assert getattr(fast.__init__.__code__, name) == getattr(reference.__code__, name), name
    assert list(fast.__init__.__code__.co_lines()) == list(reference.__code__.co_lines())
    assert sorted(fast.__init__.__globals__) == sorted(namespace)
    assert fast.__init__.__module__ is None and fast.__init__.__doc__ is None
    assert fast.__init__.__qualname__ == "M.__init__"
    msg = fast(*range(count))
    assert [getattr(msg, n) for n in names] == list(range(count))
    assert msg == fast(**dict(zip(names, range(count))))
    with pytest.raises(dataclasses.FrozenInstanceError):
        msg.f0 = 1
    with pytest.raises(TypeError, match="missing 1 required positional argument"):
        fast(*range(count - 1))


def test_the_message_classes_pickle_and_compare_as_before():
    from protocol import messages

    sample = messages.Sample(7, 1, 2, 3, 4, 5)
    assert pickle.loads(pickle.dumps(sample)) == sample
    assert repr(sample) == "Sample(period=7, adc_i1=1, adc_i2=2, adc_vdc=3, encoder=4, status=5)"
    assert sample.__init__.__code__.co_filename == "<string>"


def test_a_hil_run_start_up_compiles_no_init():
    """The start-up of `hil run` (its modules imported) calls compile() for no __init__: a class
    whose count of parameters the file lacks, or a template that stopped being used, shows here."""
    code = ("import builtins, sys\n"
            "made = []\n"
            "real = builtins.compile\n"
            "def counting(source, filename, *args, **kwargs):\n"
            "    if filename in ('<dataclass __init__>', '<string>') and '__init__' in str(source):\n"
            "        made.append(filename)\n"
            "    return real(source, filename, *args, **kwargs)\n"
            "builtins.compile = counting\n"
            "real_exec = builtins.exec\n"
            "def counting_exec(source, *args, **kwargs):\n"
            "    if isinstance(source, str) and 'def __init__' in source:\n"
            "        made.append('exec')\n"
            "    return real_exec(source, *args, **kwargs)\n"
            "builtins.exec = counting_exec\n"
            "import hil.cli.main, hil.run.runner, hil.run.console\n"
            "print(len(made))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, check=True)
    assert out.stdout.strip() == "0"
