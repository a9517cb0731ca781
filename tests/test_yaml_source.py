"""parse_yaml composes with libyaml when PyYAML has it; it must give what the pure-Python loader
gives: the same data, the same line for every key path, and for a bad document the same
ConfigError (file, line, problem)."""
from __future__ import annotations

import random
from pathlib import Path

import pytest
import yaml

from configfile import source
from configfile.source import ConfigError, parse_yaml

ROOT = Path(__file__).resolve().parent.parent
FILES = sorted(p for pattern in ("test_plans/**/*.yaml", "examples/**/*.yaml", "plant_rt/profiles/*.yaml",
                                 "tests/data/**/*.yaml")
               for p in ROOT.glob(pattern))

DOCUMENTS = {
    "empty": "",
    "comment only": "# nothing\n",
    "flow and block": "a: {b: 1, c: [1, 2.5e-6, x]}\nd:\n  - e: true\n    f: null\n  - 3\n",
    "block scalars": "a: |\n  one\n  two\nb: >-\n  folded\n  text\nc: 'q''uoted'\n",
    "anchors": "base: &b {x: 1}\nuse: *b\nlist: [*b, *b]\n",
    "explicit document": "---\na: 1\n...\n",
    "unicode": "name: \"Ω motor ✓\"\nnote: ünïcode\n",
    "keys of each kind": "1: int\n2.5: float\ntrue: bool\n'q': str\n",
    "duplicate key": "a: 1\nb: 2\na: 3\n",
    "merge key": "base: &b {x: 1}\nuse:\n  <<: *b\n",
    "bad indentation": "a:\n  b: 1\n c: 2\n",
    "mapping in a scalar": "a: b: c\n",
    "unclosed flow": "a: [1, 2\nb: 3\n",
    "tab": "a:\n\tb: 1\n",
    "control character": "a: \x07\n",
    "two documents": "a: 1\n---\nb: 2\n",
    "python tag": "a: !!python/object:os.system x\n",
    "unknown tag": "a: !thing 1\n",
    "mapping key": "? [1, 2]\n: x\n",
    # where libyaml and the pure-Python loader part (parse_yaml hands these to the latter)
    "tab inside a line": "a:\n  bit\t: 12\n",
    "question mark in a flow scalar": "a: {b: 0.?2}\n",
    "empty tag": "a: !\nb: [!, 1]\n",
    "tag of a number": "a: {b: !1.0e-4, c: 1}\n",
    "byte-order mark inside": "a: 1\n\ufeff  # note\nb: 2\n",
    "hash after a block indicator": "a: |#\n  text\nb: >-#\n  more\n",
}


def _parse(text: str, loader) -> object:
    """parse_yaml's answer with the given libyaml loader (None: the pure-Python one)."""
    saved = source._C_LOADER
    source._C_LOADER = loader
    try:
        doc = parse_yaml(text, "doc.yaml")
        return ("ok", doc.data, doc.lines)
    except ConfigError as error:
        return ("error", str(error))
    finally:
        source._C_LOADER = saved


@pytest.fixture(scope="module")
def c_loader():
    if source._C_LOADER is None:
        pytest.skip("PyYAML without libyaml: only the pure-Python loader runs")
    return source._C_LOADER


def test_libyaml_is_used_when_pyyaml_has_it():
    assert (source._C_LOADER is not None) == yaml.__with_libyaml__


@pytest.mark.parametrize("path", FILES, ids=lambda p: str(p.relative_to(ROOT)))
def test_every_yaml_file_of_the_repository_parses_the_same(path, c_loader):
    text = path.read_text()
    ours = _parse(text, c_loader)
    assert ours[0] == "ok" and ours == _parse(text, None)


@pytest.mark.parametrize("name", DOCUMENTS)
def test_each_kind_of_document_and_error_comes_out_the_same(name, c_loader):
    assert _parse(DOCUMENTS[name], c_loader) == _parse(DOCUMENTS[name], None)


def test_one_change_mutants_of_a_profile_and_a_plan_come_out_the_same(c_loader):
    """Characters deleted, doubled or replaced by YAML's syntax characters: whatever either
    loader makes of the result, the other makes the same."""
    rng = random.Random(18)
    outcomes = set()
    for path in (ROOT / "plant_rt/profiles/paper.yaml", FILES[0]):
        text = path.read_text()
        for _ in range(150):
            i = rng.randrange(len(text))
            mutant = rng.choice([text[:i] + text[i + 1:], text[:i] + text[i] + text[i:],
                                 text[:i] + rng.choice(":-[]{}#&*!|>'\"\t ,?\n") + text[i + 1:]])
            ours = _parse(mutant, c_loader)
            assert ours == _parse(mutant, None), mutant
            outcomes.add(ours[0])
    assert outcomes == {"ok", "error"}
