"""python -m bench perf_page BENCH.json [--out PAGE.md]: the performance page of one bench JSON.

The page (docs/performance.md) is written by this command, never by hand: it names the JSON it
was made from, the machine and date the JSON records, and for each of issue 18's aims the
median, the run-to-run spread (the range over the bench's batches or rounds) and a verdict:

- held: the whole spread clears the aim;
- at the threshold, not met: the aim lies inside the spread;
- not met: the whole spread misses it;
- not judged: the JSON holds a median but no spread (nothing says how far a run strays).

tests/test_performance_page.py checks that the page is what this makes from the JSON it names.
"""
from __future__ import annotations

import argparse
import json
import math
import operator
from pathlib import Path
from typing import Any, Callable

from configfile.dataclass_methods import dataclass

HELD = "held"
AT_THRESHOLD = "at the threshold, not met"
NOT_MET = "not met"
NOT_JUDGED = "not judged (no spread recorded)"
NOT_MEASURED = "not measured"

_INTERLEAVED = ("session", "lockstep", "stub, stub+log, plant_only interleaved")


@dataclass(frozen=True)
class Aim:
    """One aim: where its median and spread sit in the JSON, and the bound they must clear."""

    text: str                      # the aim in words, as the issue sets it
    where: tuple[str, ...]         # keys down to the dict holding the figures
    median: tuple[str, ...]        # keys below `where` to the median
    spread: tuple[tuple[str, ...], ...]  # keys below `where`: one path to [low, high], or two paths
    relation: str                  # "<", "<=", ">", ">="
    bound: float
    unit: str
    digits: int                    # decimals printed

    def clears(self, value: float) -> bool:
        compare: Callable[[float, float], bool] = {
            "<": operator.lt, "<=": operator.le, ">": operator.gt, ">=": operator.ge}[self.relation]
        return compare(value, self.bound)


AIMS = (
    Aim("logged in-process session (`stub` + full log) within 2x of the plant alone's period",
        _INTERLEAVED, ("stub+log_vs_plant_only",), (("per_round_ratio_range",),), "<=", 2.0, "x", 2),
    Aim("100,000 periods/s with the full log (`stub` + full log)",
        _INTERLEAVED, ("stub+log", "periods_per_s"), (("stub+log", "batch_periods_per_s_range"),),
        ">=", 100_000, "periods/s", 0),
    Aim("`stub-pty` at least 0.8 of the bare pty echo's round trips",
        ("session", "stub_pty_vs_bare_pty"), ("stub_pty_vs_bare",), (("per_batch_ratio_range",),),
        ">=", 0.8, "of the echo", 3),
    Aim("`hil run` start-up (a two-period plan, process to exit) under 0.3 s",
        ("session", "hil_run_startup"), ("median_s",), (("min_s",), ("max_s",)), "<", 0.3, "s", 3),
)


def _dig(data: Any, keys: tuple[str, ...]) -> Any:
    for key in keys:
        if not isinstance(data, dict) or key not in data:
            return None
        data = data[key]
    return data


def _number(value: Any) -> float | None:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return None
    return float(value) if math.isfinite(value) else None


def judge(aim: Aim, bench: dict) -> tuple[float | None, tuple[float, float] | None, str]:
    """(median, (low, high) or None, verdict) of one aim in a bench JSON."""
    block = _dig(bench, aim.where)
    if not isinstance(block, dict):
        return None, None, NOT_MEASURED
    if "error" in block:
        return None, None, f"{NOT_MEASURED}: {block['error']}"
    median = _number(_dig(block, aim.median))
    if median is None:
        return None, None, NOT_MEASURED
    if len(aim.spread) == 2:
        ends = [_dig(block, aim.spread[0]), _dig(block, aim.spread[1])]
    else:
        ends = _dig(block, aim.spread[0])
    if not isinstance(ends, list) or len(ends) != 2 or None in map(_number, ends):
        return median, None, NOT_JUDGED
    low, high = sorted(map(float, ends))
    cleared = [aim.clears(low), aim.clears(high)]
    verdict = HELD if all(cleared) else NOT_MET if not any(cleared) else AT_THRESHOLD
    return median, (low, high), verdict


def _fmt(value: float, digits: int) -> str:
    return f"{value:,.{digits}f}"


def render(bench: dict, json_name: str) -> str:
    """The page's Markdown, from the bench JSON `bench` read from `json_name`."""
    run = bench.get("_run") if isinstance(bench.get("_run"), dict) else {}
    lines = [
        "# Performance",
        "",
        f"<!-- Written by `python -m bench perf_page {json_name} --out docs/performance.md`; "
        "do not edit: run the command again on a new bench JSON. -->",
        "",
        f"Figures from [{json_name}]({Path(json_name).name}), written by "
        f"`{run.get('command', 'python -m bench')}`; this page is made from it by "
        f"`python -m bench perf_page {json_name} --out docs/performance.md`.",
        "",
        f"- machine: {run.get('machine', 'not recorded')}",
        f"- system: {run.get('system', 'not recorded')}, Python {run.get('python', 'not recorded')}",
        f"- measured (UTC): {run.get('date_utc', 'not recorded')}",
        "",
        "Absolute rates are this machine's under its load at the time; ratios carry over better.",
        "An aim is **held** only when the whole run-to-run spread (the range over the bench's",
        "batches or rounds) clears it, **at the threshold, not met** when the aim lies inside",
        "the spread, and **not met** when the whole spread misses it.",
        "",
        "| aim | bound | median | spread | verdict |",
        "|---|---|---|---|---|",
    ]
    for aim in AIMS:
        median, spread, verdict = judge(aim, bench)
        bound = f"{aim.relation} {_fmt(aim.bound, aim.digits)} {aim.unit}"
        med = "-" if median is None else f"{_fmt(median, aim.digits)} {aim.unit}"
        rng = "-" if spread is None else f"{_fmt(spread[0], aim.digits)} to {_fmt(spread[1], aim.digits)}"
        lines.append(f"| {aim.text} | {bound} | {med} | {rng} | **{verdict}** |")
    lines += _reliability(bench.get("hostile_board"))
    lines += ["", "Every other figure of the run is in the JSON; `python -m bench NAME [--quick]`",
              "measures one bench module again.", ""]
    return "\n".join(lines)


#: The hostile-board soak's figures, in the order the page shows them.
_SOAK_ROWS = (("sessions", "sessions"), ("crashes", "crashes (an exception the bench does not name)"),
              ("hangs", "hangs (a session past its own bound)"),
              ("unnamed", "ends without a named cause"), ("logs_readable", "logs readable"),
              ("not_safe", "plants not safe-stated at the end"))


def _reliability(soak: Any) -> list[str]:
    """The hostile-board soak (bench/hostile_board.py) as a table: lockstep and real time."""
    lines = ["", "## Reliability: hostile boards", ""]
    if not isinstance(soak, dict):
        return lines + ["Not measured in this JSON (`python -m bench hostile_board`)."]
    lines += ["Bench sessions against seeded boards that answer with random mixes of valid,",
              "malformed, out-of-order and out-of-range frames (`python -m bench hostile_board`;",
              "the bounded version runs in the test suite, `tests/test_hostile_board.py`).", "",
              "| figure | lockstep | real time |", "|---|---|---|"]
    realtime = soak.get("realtime") if isinstance(soak.get("realtime"), dict) else {}
    for key, text in _SOAK_ROWS:
        lines.append(f"| {text} | {_count(soak.get(key))} | {_count(realtime.get(key))} |")
    ends = soak.get("ends_by_kind")
    if isinstance(ends, dict) and ends:
        listed = ", ".join(f"{kind} {n}" for kind, n in sorted(ends.items(), key=lambda kv: -kv[1]))
        lines += ["", f"How the lockstep sessions ended: {listed}."]
    return lines


def _count(value: Any) -> str:
    number = _number(value)
    return "-" if number is None else f"{int(number):,}"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m bench perf_page", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("json", help="a JSON written by python -m bench (or hil bench)")
    parser.add_argument("--out", help="write the page here (default: standard output)")
    args = parser.parse_args(argv)
    try:
        bench = json.loads(Path(args.json).read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        parser.error(f"{args.json}: {exc}")
    if not isinstance(bench, dict):
        parser.error(f"{args.json}: not a JSON object of bench results")
    page = render(bench, args.json)
    if args.out:
        Path(args.out).write_text(page, encoding="utf-8")
    else:
        print(page, end="")
    return 0
