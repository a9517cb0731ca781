"""Sweep files: which plans, over which link, across which parameter space, from which seed.

A sweep file is data, never code: YAML through configfile's safe loader, its structure checked
with JSON Schema (configfile.schema.SchemaChecker) and every error a ConfigError naming the
file, the line and the key. Everything sits under one top-level key, ``sweep:``, so that
``hil run test_plans/`` (hil.plans.format.looks_like_plan: a plan has 'name' or 'steps' at the
top) never mistakes a sweep for a plan.

    sweep:
      name: sensorless-tolerances
      plans: [../04_sensorless_ekf.yaml]      # relative to this file
      link: stub                              # a link that can run many times at once
      board: ../boards/my-board.yaml          # optional board file for every run (docs/boards.md)
      seed: 16
      sampling: latin_hypercube               # or monte_carlo
      runs: 64                                # samples per grid point
      set:                                    # fixed values, applied to every run
        plan.steps[0].param_set.current_offset_counts: 2048
      parameters:
        profile.motor.resistance_ohm: {uniform: {low: 0.42, high: 0.51}}
        profile.motor.flux_linkage_wb: {normal: {mean: 0.0928, sd: 0.0015, low: 0.088, high: 0.098}}
        profile.load.torque_nm: {grid: [0.0, 0.5]}
        profile.sensors.current.phases: {choice: [ab, ac]}
      logs: {failed: true, passing: 0.1}       # MCAP logs kept: failed runs, a share of passing ones

A parameter name says what it sets: ``profile.SECTION.KEY...`` is a bench-profile value (the
plan's ``overrides``), ``plan.KEY...`` any value of the plan file itself by its key path
(``plan.steps[5].run.duration_s``); a missing last key is added (a ``param_set`` entry).
Every plan is built once with the nominal values at load time, so a parameter that does not
fit a plan is reported against the sweep file's line.
"""
from __future__ import annotations

import copy
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from configfile.schema import BOOLEAN, FRACTION, NAME, NUMBER, POSITIVE_INT, SchemaChecker, obj
from configfile.source import ConfigError, YamlDocument, load_yaml, parse_yaml

SWEEP_KEY = "sweep"
SAMPLING = ("monte_carlo", "latin_hypercube")
# Links that can run many instances at once on one machine (each run starts its own board).
PARALLEL_LINK_PATTERN = r"^(stub|stub-pty|stub-can|qemu|lib:.+|exec:.+|qemu:.+)$"
PARALLEL_LINK_WORDS = "stub, stub-pty, stub-can, qemu, lib:PATH, exec:PATH or qemu:IMAGE " \
                      "(a physical board runs one plan at a time: see docs/scale.md)"
# Links that run a program named by the sweep file on this machine: a sweep from someone else
# must not run their program unasked (hil sweep --allow-programs; docs/scale.md). qemu:
# too: its image runs with semihosting on, which reaches the host's files.
PROGRAM_LINK_PREFIXES = ("exec:", "lib:", "qemu:")
PARAM_PATTERN = r"^(profile|plan)\.[A-Za-z_][A-Za-z0-9_]*(\[[0-9]+\]|\.[A-Za-z_][A-Za-z0-9_]*)*$"
PARAM_WORDS = "profile.SECTION.KEY or plan.KEY[INDEX].KEY..."

_SCALAR = {"type": ["number", "string", "boolean"]}
_GRID = {"oneOf": [{"type": "array", "minItems": 1, "items": _SCALAR},
                   obj({"from": NUMBER, "to": NUMBER, "steps": POSITIVE_INT}, ["from", "to", "steps"])]}
DISTRIBUTIONS = {
    "grid": _GRID,
    "uniform": obj({"low": NUMBER, "high": NUMBER}, ["low", "high"]),
    "normal": obj({"mean": NUMBER, "sd": {"type": "number", "exclusiveMinimum": 0},
                   "low": NUMBER, "high": NUMBER}, ["mean", "sd"]),
    "choice": {"oneOf": [{"type": "array", "minItems": 1, "items": _SCALAR},
                         obj({"values": {"type": "array", "minItems": 1, "items": _SCALAR},
                              "weights": {"type": "array", "minItems": 1,
                                          "items": {"type": "number", "minimum": 0}}},
                             ["values"])]},
}
_PARAMETER = {"type": "object", "minProperties": 1, "maxProperties": 1,
              "properties": DISTRIBUTIONS, "additionalProperties": False}

SWEEP_SCHEMA = obj({
    SWEEP_KEY: obj({
        "name": NAME,
        "description": {"type": "string"},
        "plans": {"type": "array", "minItems": 1, "items": NAME},
        "link": {"type": "string", "pattern": PARALLEL_LINK_PATTERN},
        "board": NAME,
        "seed": {"type": "integer", "minimum": 0},
        "sampling": {"enum": list(SAMPLING)},
        "runs": POSITIVE_INT,
        "retries": {"type": "integer", "minimum": 0, "maximum": 10},
        "set": {"type": "object", "propertyNames": {"pattern": PARAM_PATTERN},
                "additionalProperties": _SCALAR},
        "parameters": {"type": "object", "propertyNames": {"pattern": PARAM_PATTERN},
                       "additionalProperties": _PARAMETER},
        "logs": obj({"failed": BOOLEAN, "passing": FRACTION}),
    }, ["name", "plans", "seed"]),
}, [SWEEP_KEY])


@dataclass(frozen=True)
class Parameter:
    name: str
    kind: str                  # grid | uniform | normal | choice
    spec: Any
    line: int | None

    @property
    def is_grid(self) -> bool:
        return self.kind == "grid"

    def grid_values(self) -> list[Any]:
        if isinstance(self.spec, list):
            return list(self.spec)
        a, b, n = float(self.spec["from"]), float(self.spec["to"]), int(self.spec["steps"])
        return [a] if n == 1 else [a + (b - a) * i / (n - 1) for i in range(n)]

    def nominal(self) -> Any:
        """A value inside the space (load-time validation of every plan)."""
        if self.kind == "grid":
            return self.grid_values()[0]
        if self.kind == "uniform":
            return 0.5 * (float(self.spec["low"]) + float(self.spec["high"]))
        if self.kind == "normal":
            m = float(self.spec["mean"])
            return min(max(m, float(self.spec.get("low", m))), float(self.spec.get("high", m)))
        return self.choices()[0][0]

    def choices(self) -> tuple[list[Any], list[float]]:
        values = self.spec if isinstance(self.spec, list) else self.spec["values"]
        weights = [1.0] * len(values) if isinstance(self.spec, list) else \
            [float(w) for w in self.spec.get("weights", [1.0] * len(values))]
        return list(values), weights


@dataclass(frozen=True)
class Sweep:
    name: str
    description: str
    source_path: Path
    plan_paths: tuple[Path, ...]
    link: str
    seed: int
    sampling: str
    runs: int                       # samples per grid point
    retries: int
    fixed: dict[str, Any]
    parameters: tuple[Parameter, ...]
    keep_failed_logs: bool = True
    keep_passing_logs: float = 0.1
    board_path: Path | None = None  # `board:`, relative to the sweep file; None: each plan's own
    lines: dict[str, int] = field(default_factory=dict)
    link_line: int | None = None    # the line of `link:` (None: the default, stub)

    @property
    def program_link(self) -> bool:
        """True when the link runs a program the sweep file names (PROGRAM_LINK_PREFIXES)."""
        return self.link.startswith(PROGRAM_LINK_PREFIXES)

    @property
    def grid(self) -> tuple[Parameter, ...]:
        return tuple(p for p in self.parameters if p.is_grid)

    @property
    def sampled(self) -> tuple[Parameter, ...]:
        return tuple(p for p in self.parameters if not p.is_grid)


_KEY_RE = re.compile(r"\.?([A-Za-z_][A-Za-z0-9_]*)|\[([0-9]+)\]")


def key_path(name: str) -> tuple[str, tuple[Any, ...]]:
    """'plan.steps[5].run.duration_s' -> ('plan', ('steps', 5, 'run', 'duration_s'))."""
    parts: list[Any] = []
    for m in _KEY_RE.finditer(name):
        parts.append(m.group(1) if m.group(1) is not None else int(m.group(2)))
    return parts[0], tuple(parts[1:])


def apply_values(plan_data: dict, values: dict[str, Any]) -> dict:
    """A copy of a plan's YAML data with the sweep's values set. KeyError/IndexError/TypeError
    (with the parameter's name as the first argument) when a path does not fit the plan."""
    data = copy.deepcopy(plan_data)
    for name, value in values.items():
        root, path = key_path(name)
        if root == "profile":
            node = data.setdefault("overrides", {})
            if not isinstance(node, dict):
                raise TypeError(name, "the plan's 'overrides' is not a mapping")
            for part in path[:-1]:
                node = node.setdefault(part, {})
                if not isinstance(node, dict):
                    raise TypeError(name, f"overrides '{part}' is not a mapping")
            node[path[-1]] = value
            continue
        node: Any = data
        for i, part in enumerate(path[:-1]):
            try:
                node = node[part]
            except (KeyError, IndexError, TypeError):
                where = "".join(f"[{p}]" if isinstance(p, int) else f".{p}" for p in path[:i + 1])
                raise KeyError(name, f"the plan has no '{where.lstrip('.')}'") from None
        last = path[-1]
        if isinstance(node, list):
            if not isinstance(last, int) or last >= len(node):
                raise KeyError(name, f"the plan has no item {last} there")
            node[last] = value
        elif isinstance(node, dict):
            node[last] = value
        else:
            raise TypeError(name, f"the plan's value before '{last}' is not a mapping or a list")
    return data


def load_sweep(path: str | Path) -> Sweep:
    return _build(load_yaml(path), Path(path))


def parse_sweep(text: str, source: str = "<string>", base_dir: Path | None = None) -> Sweep:
    path = Path(source) if base_dir is None else Path(base_dir) / Path(source).name
    return _build(parse_yaml(text, source), path)


def looks_like_sweep(path: str | Path) -> bool:
    try:
        data = load_yaml(path).data
    except ConfigError:
        return False
    return isinstance(data, dict) and SWEEP_KEY in data


def _build(doc: YamlDocument, path: Path) -> Sweep:
    data = doc.data
    if not isinstance(data, dict) or SWEEP_KEY not in data:
        raise doc.error((), "a sweep file is a mapping with one top-level key 'sweep' "
                            "(name, plans, seed, parameters, ...)")
    checker = SchemaChecker(doc, {PARALLEL_LINK_PATTERN: PARALLEL_LINK_WORDS,
                                  PARAM_PATTERN: PARAM_WORDS})
    # propertyNames errors carry no path to the key: check names first, by hand.
    s = data[SWEEP_KEY]
    if isinstance(s, dict):
        for section in ("set", "parameters"):
            for name in (s.get(section) or {}) if isinstance(s.get(section), dict) else {}:
                if not isinstance(name, str) or not re.match(PARAM_PATTERN, name):
                    raise doc.error((SWEEP_KEY, section, name),
                                    f"not a parameter name (expected {PARAM_WORDS})")
    checker.check(SWEEP_SCHEMA, data, ())
    base = (SWEEP_KEY,)
    params: list[Parameter] = []
    for name, spec in (s.get("parameters") or {}).items():
        kind, body = next(iter(spec.items()))
        p = Parameter(name, kind, body, doc.line_of(base + ("parameters", name)))
        where = base + ("parameters", name, kind)
        if kind == "uniform" and not float(body["low"]) < float(body["high"]):
            raise doc.error(where, f"low ({body['low']}) must be below high ({body['high']})")
        if kind == "normal":
            lo, hi = body.get("low"), body.get("high")
            if lo is not None and hi is not None and not float(lo) < float(hi):
                raise doc.error(where, f"low ({lo}) must be below high ({hi})")
        if kind == "choice" and isinstance(body, dict) and "weights" in body:
            if len(body["weights"]) != len(body["values"]):
                raise doc.error(where + ("weights",), f"{len(body['weights'])} weights for "
                                                      f"{len(body['values'])} values")
            if sum(body["weights"]) <= 0:
                raise doc.error(where + ("weights",), "the weights must not all be zero")
        params.append(p)
    fixed = dict(s.get("set") or {})
    for name in fixed:
        if name in dict((p.name, p) for p in params):
            raise doc.error(base + ("set", name), "is also a swept parameter")
    plan_paths = tuple((path.parent / p).resolve() for p in s["plans"])
    for i, pp in enumerate(plan_paths):
        if not pp.is_file():
            raise doc.error(base + ("plans", i), f"plan file not found: {pp}")
    board_path = None
    if s.get("board") is not None:
        board_path = (path.parent / s["board"]).resolve()
        from hil.boards import load_board

        load_board(board_path)              # a bad board file fails the sweep at load
    sampled = [p for p in params if not p.is_grid]
    if "runs" in s and not sampled:
        pass  # runs repeats each grid point (different seeds)
    sweep = Sweep(
        name=s["name"], description=str(s.get("description", "")).strip(), source_path=path,
        plan_paths=plan_paths, link=s.get("link", "stub"), board_path=board_path,
        seed=int(s["seed"]),
        sampling=s.get("sampling", "monte_carlo"), runs=int(s.get("runs", 1)),
        retries=int(s.get("retries", 2)), fixed=fixed, parameters=tuple(params),
        keep_failed_logs=bool((s.get("logs") or {}).get("failed", True)),
        keep_passing_logs=float((s.get("logs") or {}).get("passing", 0.1)),
        lines={**{n: doc.line_of(base + ("set", n)) for n in fixed},
               **{p.name: p.line for p in params}},
        link_line=doc.line_of(base + ("link",)) if "link" in s else None)
    _check_plans(sweep, doc)
    return sweep


def _check_plans(sweep: Sweep, doc: YamlDocument) -> None:
    """Every plan built with the nominal values (and its profile loaded): a parameter that does
    not fit a plan is an error at the sweep file's line of that parameter."""
    nominal = {**sweep.fixed, **{p.name: p.nominal() for p in sweep.parameters}}
    section = {n: ("set" if n in sweep.fixed else "parameters") for n in nominal}
    for plan_path in sweep.plan_paths:
        plan_doc = load_yaml(plan_path)
        for name in nominal:
            try:
                apply_values(plan_doc.data, {name: nominal[name]})
            except (KeyError, IndexError, TypeError) as exc:
                raise doc.error((SWEEP_KEY, section[name], name),
                                f"does not fit plan {plan_path.name}: {exc.args[-1]}") from None
        for name in nominal:  # one at a time, so an error names its parameter
            try:
                build_plan(plan_doc, plan_path, {**sweep.fixed, name: nominal[name]}, check_profile=True)
            except ConfigError as exc:
                raise doc.error((SWEEP_KEY, section[name], name),
                                f"makes plan {plan_path.name} invalid: {exc}") from None


def build_plan(plan_doc: YamlDocument, plan_path: Path, values: dict[str, Any],
               check_profile: bool = False):
    """The plan with the sweep's values applied, validated like a plan file (lines of the
    original file); with check_profile its bench profile (with the overrides) is loaded too."""
    from hil.plans.format import _build as build_plan_document  # the plan loader, on data
    from hil.run.runner import profile_for

    data = apply_values(plan_doc.data, values)
    plan = build_plan_document(YamlDocument(data, plan_doc.source, plan_doc.lines), plan_path)
    if check_profile:
        profile_for(plan)
    return plan
