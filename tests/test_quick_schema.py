"""The quick acceptance check (configfile.schema.schema_accepts) that lets a valid plan or
profile load without importing jsonschema: it must never accept what jsonschema rejects, and
it must accept every valid document of the repository (else the fast path is silently lost).
Invalid documents still go to jsonschema, so their errors are the ones tests/test_plan_format.py
and tests/test_plant_profile.py pin down."""
from __future__ import annotations

import math
import random
import subprocess
import sys
from pathlib import Path

import pytest
from jsonschema import Draft202012Validator

from configfile.source import load_yaml
from hil.faults.catalog import FAULTS
from hil.plans.format import CHECK_SCHEMAS, LOAD_SCHEMAS, PLAN_SCHEMA, PLOT_SCHEMA, STEP_SCHEMAS
from hil.session.policy import SESSION_SCHEMA
from configfile.schema import nullable
from configfile.schema import _accepts, _Undecided, schema_accepts
from plant_rt.profile import profile_schema

REPO = Path(__file__).resolve().parents[1]


def _bench_profile_schema() -> dict:
    schema = profile_schema()
    schema["properties"]["session"] = nullable(SESSION_SCHEMA)
    return schema


def _valid(schema, value) -> bool:
    return next(iter(Draft202012Validator(schema).iter_errors(value)), None) is None


def _pairs_of_plan(data: dict):
    """(schema, value) for a plan and each part hil.plans.format checks on its own."""
    yield PLAN_SCHEMA, data
    for step in data.get("steps", []):
        if not (isinstance(step, dict) and len(step) == 1):
            continue
        kind, body = next(iter(step.items()))
        if kind not in STEP_SCHEMAS:
            continue
        yield STEP_SCHEMAS[kind], body
        if kind == "load" and isinstance(body, dict) and body.get("type") in LOAD_SCHEMAS:
            yield LOAD_SCHEMAS[body["type"]], body
        if kind == "check" and isinstance(body, dict) and body.get("kind") in CHECK_SCHEMAS:
            yield CHECK_SCHEMAS[body["kind"]], body
        if kind == "fault" and isinstance(body, dict) and body.get("name") in FAULTS:
            yield FAULTS[body["name"]], {k: v for k, v in body.items() if k != "name"}
    for plot in data.get("plots", []) if isinstance(data.get("plots"), list) else []:
        yield PLOT_SCHEMA, plot


def _documents():
    """Every plan and profile of the repository, with the schemas each is checked against."""
    from hil.plans import plan_formulas
    from hil.plans.format import resolve_profile

    for path in sorted((REPO / "test_plans").rglob("*.y*ml")):
        doc = load_yaml(path)
        data = doc.data
        if isinstance(data, dict) and "steps" in data:
            if plan_formulas.has_formulas(data):
                # what the loader validates: the plan with its formulas evaluated (on its
                # first profile)
                label, profile, board = plan_formulas.plan_contexts(doc, path, resolve_profile)[0]
                data = plan_formulas.substitute(
                    doc, plan_formulas.named_values(profile, board, label))[0]
            for schema, value in _pairs_of_plan(data):
                yield path.name, schema, value
    for path in sorted((REPO / "plant_rt" / "profiles").glob("*.yaml")):
        yield path.name, _bench_profile_schema(), load_yaml(path).data or {}


DOCUMENTS = list(_documents())
_ODD = [None, True, False, 0, 1, -1, 2, 0.0, 1.0, 0.5, -0.5, 1e-9, 1e9, 4096, math.inf, math.nan,
        "", "x", "1e-3", "stub", "encoder", "a_high", "adc_i1", [], [1], ["GATES", "GATES"],
        ["GATES", "DUTY"], ["x"], {}, {"value": 1}, {"value": 1, "unit": "rpm"}]


def _mutants(value, limit: int, depth: int = 0):
    """`value` with one thing changed, at most `limit` levels down: a key dropped or added, an
    item dropped or repeated, a value replaced by an odd one."""
    if depth > limit:
        return
    if isinstance(value, dict):
        for key in value:
            dropped = dict(value)
            del dropped[key]
            yield dropped
            for odd in _ODD:
                yield {**value, key: odd}
            for inner in _mutants(value[key], limit, depth + 1):
                yield {**value, key: inner}
        yield {**value, "unknown_key": 1}
    elif isinstance(value, list):
        for i, item in enumerate(value):
            yield value[:i] + value[i + 1:]
            for odd in _ODD[:12]:
                yield value[:i] + [odd] + value[i + 1:]
            for inner in _mutants(item, limit, depth + 1):
                yield value[:i] + [inner] + value[i + 1:]
        yield value + [value[-1]] if value else [None]


def _sample_of_mutants(count: int) -> list[tuple[str, dict, object]]:
    """A fixed sample of the distinct one-change mutants of every document (a whole plan only
    at its top level: its steps are mutated as the step schemas' documents)."""
    every: dict[tuple[int, str], tuple[str, dict, object]] = {}
    for name, schema, value in DOCUMENTS:
        for mutant in _mutants(value, 0 if schema is PLAN_SCHEMA else 3):
            every.setdefault((id(schema), repr(mutant)), (name, schema, mutant))
    keys = sorted(every, key=lambda k: (k[1], k[0]))
    return [every[k] for k in random.Random(18).sample(keys, min(count, len(keys)))]


def test_every_plan_and_profile_of_the_repository_is_accepted_without_jsonschema():
    assert len(DOCUMENTS) > 100
    for name, schema, value in DOCUMENTS:
        assert _valid(schema, value), name
        assert schema_accepts(schema, value), f"{name}: the quick check left a valid document to jsonschema"


def test_the_quick_check_agrees_with_jsonschema_on_one_change_mutants():
    """Where the quick check decides, it decides as jsonschema does; where it cannot (a value or
    keyword it does not model) schema_accepts is False and jsonschema decides."""
    validators: dict[int, Draft202012Validator] = {}
    decided = undecided = invalid = 0
    for name, schema, mutant in _sample_of_mutants(20000):
        validator = validators.setdefault(id(schema), Draft202012Validator(schema))
        valid = validator.is_valid(mutant)
        invalid += not valid
        try:
            quick = _accepts(schema, mutant)
        except _Undecided:
            undecided += 1
            assert not schema_accepts(schema, mutant)
            continue
        decided += 1
        assert quick == valid, f"{name}: {mutant!r}"
        assert schema_accepts(schema, mutant) == valid
    assert decided > 20 * undecided and invalid > 5000, (decided, undecided, invalid)


@pytest.mark.parametrize("schema,value,valid", [
    ({"type": "integer"}, 3.0, True),            # Draft 2020-12: a number with no fraction
    ({"type": "integer"}, True, False),          # a bool is neither integer nor number
    ({"type": "number", "minimum": 0}, False, False),
    ({"minimum": 0}, False, True),               # bounds apply to numbers only
    ({"enum": [1]}, True, False),                # jsonschema's equal: True is not 1
    ({"enum": [1]}, 1.0, True),
    ({"enum": ["a"]}, "a", True),
    ({"type": "array", "uniqueItems": True}, ["a", "a"], False),
    ({"pattern": "^a"}, "ba", False),
    ({"pattern": "a"}, "ba", True),              # re.search, not re.match
    ({"oneOf": [{"type": "number"}, {"type": "integer"}]}, 1, False),
    ({"type": "object", "additionalProperties": {"type": "number"}}, {"a": "x"}, False),
])
def test_keyword_semantics_follow_jsonschema(schema, value, valid):
    assert _valid(schema, value) == valid
    assert _accepts(schema, value) == valid


def test_what_the_quick_check_does_not_model_goes_to_jsonschema():
    class Number(float):
        pass
    for schema, value in [({"type": "number"}, Number(1.0)),        # not a plain YAML value
                          ({"$ref": "#/$defs/x"}, 1),                # keyword it does not know
                          ({"type": "array", "uniqueItems": True}, [1, 2]),
                          ({"enum": [[1]]}, [1])]:
        with pytest.raises(_Undecided):
            _accepts(schema, value)
        assert not schema_accepts(schema, value)


def test_hil_run_of_a_plan_without_faults_imports_neither_jsonschema_nor_protobuf(tmp_path):
    """Valid plans and profiles pass the quick check; the MCAP schemas are serialized by hand
    (hil.logs.mcap_writer); fault arguments are checked with jsonschema only when wrong. Nor
    shutil (with bz2 and lzma), which argparse imports for the terminal width alone
    (hil.cli.main._HelpFormatter finds it without)."""
    plan = tmp_path / "one.yaml"
    plan.write_text("name: two-periods\nsteps:\n  - run: {duration_s: 100.0e-6}\n"
                    "  - check: {name: ran, kind: final_value, signal: plant.speed_rpm, "
                    "limits: {low: -1, high: 1, unit: rpm}}\n")
    code = ("import sys\nfrom hil.cli.main import main\n"
            f"rc = main(['run', {str(plan)!r}, '--out', {str(tmp_path / 'out')!r}, '--no-progress'])\n"
            "print(rc, sorted(m for m in sys.modules if m.split('.')[0] in "
            "('jsonschema', 'referencing', 'google', 'shutil', 'bz2', 'lzma')))\n")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=120, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.splitlines()[-1] == "0 []"
    assert (tmp_path / "out" / "two-periods" / "log.mcap").stat().st_size > 0


def test_a_keyword_it_does_not_model_leaves_the_whole_schema_undecided():
    """additionalProperties means something else beside patternProperties: under `not`, a
    False computed without it would turn into a wrong True."""
    schema = {"not": {"type": "object", "additionalProperties": False,
                      "patternProperties": {"^x": {}}}}
    assert not _valid(schema, {"x1": 1})
    with pytest.raises(_Undecided):
        _accepts(schema, {"x1": 1})
    assert not schema_accepts(schema, {"x1": 1})
