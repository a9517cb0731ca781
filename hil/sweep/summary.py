"""What a sweep's table says: yields with Wilson intervals, and which parameters drive failures.

- Yield of a plan: runs that PASSed (MARGINAL counts as pass) over the runs with a verdict;
  lost runs (no result: the executor gave up) are counted apart, never as failures.
- Yield of a check: runs where it passed over the runs where it was evaluated (PASS,
  MARGINAL or FAIL; ERROR and SKIPPED are counted apart). A finding (a check that informs and
  cannot fail, outcome INFO) has no yield: its measured values, their spread and the
  parameters that drive them are the result, over the runs that measured it.
- Wilson score interval at 95 % (z = 1.959964): right at 0 % and 100 %, where the normal
  approximation collapses to a zero-width interval.
- Drivers: for every check and every numeric parameter, Spearman's rank correlation of the
  parameter with the measured value and with the failure indicator (ties get average ranks).
  The strongest |rho| against failure (against the value when nothing failed) ranks first.
"""
from __future__ import annotations

import math
from collections import defaultdict
from typing import Any, Iterable

import numpy as np

Z95 = 1.959963984540054
PASSING = ("PASS", "MARGINAL")
EVALUATED = ("PASS", "MARGINAL", "FAIL")


def wilson(k: int, n: int, z: float = Z95) -> tuple[float, float]:
    if n <= 0:
        return (math.nan, math.nan)
    p = k / n
    z2 = z * z
    denom = 1.0 + z2 / n
    centre = (p + z2 / (2 * n)) / denom
    half = z / denom * math.sqrt(p * (1 - p) / n + z2 / (4 * n * n))
    return (max(0.0, centre - half), min(1.0, centre + half))


def ranks(x: np.ndarray) -> np.ndarray:
    """1-based ranks, ties sharing their average rank."""
    order = np.argsort(x, kind="mergesort")
    r = np.empty(len(x))
    xs = x[order]
    i = 0
    while i < len(x):
        j = i
        while j + 1 < len(x) and xs[j + 1] == xs[i]:
            j += 1
        r[order[i:j + 1]] = 0.5 * (i + j) + 1.0
        i = j + 1
    return r


def spearman(x: Iterable[float], y: Iterable[float]) -> float | None:
    """Spearman's rho (Pearson's r of the ranks); None with fewer than 3 pairs or a constant."""
    x = np.asarray(list(x), float)
    y = np.asarray(list(y), float)
    ok = np.isfinite(x) & np.isfinite(y)
    x, y = x[ok], y[ok]
    if len(x) < 3:
        return None
    rx, ry = ranks(x), ranks(y)
    rx -= rx.mean()
    ry -= ry.mean()
    den = math.sqrt(float(rx @ rx) * float(ry @ ry))
    if den == 0.0:
        return None
    return float(rx @ ry) / den


def _numeric(v: Any) -> float | None:
    if isinstance(v, bool):
        return float(v)
    if isinstance(v, (int, float)):
        return float(v)
    return None


def summarize(rows: list[dict], parameters: list[str]) -> dict:
    plans: dict[str, dict] = {}
    checks: dict[tuple[str, str], dict] = {}
    by_plan: dict[str, list[dict]] = defaultdict(list)
    for r in rows:
        by_plan[r.get("plan") or r.get("plan_file")].append(r)
    for plan, prs in by_plan.items():
        lost = sum(1 for r in prs if r.get("lost"))
        judged = [r for r in prs if not r.get("lost")]
        k = sum(1 for r in judged if r["outcome"] in PASSING)
        n = len(judged)
        lo, hi = wilson(k, n)
        counts: dict[str, int] = defaultdict(int)
        for r in prs:
            counts["LOST" if r.get("lost") else r["outcome"]] += 1
        plans[plan] = {"plan": plan, "runs": len(prs), "judged": n, "passed": k, "lost": lost,
                       "yield": k / n if n else math.nan, "ci_low": lo, "ci_high": hi,
                       "outcomes": dict(counts)}
        names: list[str] = []
        for r in judged:
            for c in r["checks"]:
                if c["name"] not in names:
                    names.append(c["name"])
        for name in names:
            entries = []   # (row, check)
            for r in judged:
                c = next((c for c in r["checks"] if c["name"] == name), None)
                if c is not None:
                    entries.append((r, c))
            ev = [(r, c) for r, c in entries if c["outcome"] in EVALUATED]
            found = [(r, c) for r, c in entries if c["outcome"] == "INFO"]
            finding = bool(found) and not ev
            kc = sum(1 for _, c in ev if c["outcome"] in PASSING)
            nc = len(ev)
            lo, hi = wilson(kc, nc)
            scored = found if finding else ev       # the runs whose values are summarised
            measured = [c["measured"] for _, c in scored if c["measured"] is not None]
            failed_runs = sorted(r["index"] for r, c in ev if c["outcome"] == "FAIL")
            drivers = []
            for p in parameters:
                xs = [_numeric(r["params"].get(p)) for r, _ in scored]
                if all(x is None for x in xs):
                    continue
                xs = [math.nan if x is None else x for x in xs]
                ys = [math.nan if c["measured"] is None else c["measured"] for _, c in scored]
                fs = [0.0 if c["outcome"] in PASSING else 1.0 for _, c in scored]
                rho_v = spearman(xs, ys)
                rho_f = None if finding else spearman(xs, fs)
                if rho_v is None and rho_f is None:
                    continue
                drivers.append({"parameter": p, "rho_value": rho_v, "rho_fail": rho_f})
            drivers.sort(key=lambda d: (-abs(d["rho_fail"] or 0.0) if failed_runs else 0.0,
                                        -abs(d["rho_value"] or 0.0)))
            unit = next((c["unit"] for _, c in entries), "")
            other: dict[str, int] = defaultdict(int)
            for _, c in entries:
                if c["outcome"] not in EVALUATED and not (finding and c["outcome"] == "INFO"):
                    other[c["outcome"]] += 1
            checks[(plan, name)] = {
                "plan": plan, "check": name, "unit": unit, "evaluated": nc, "passed": kc,
                "finding": finding, "measured_runs": len(scored),
                "failed": nc - kc, "not_evaluated": dict(other),
                "yield": kc / nc if nc else math.nan, "ci_low": lo, "ci_high": hi,
                "min": min(measured) if measured else None,
                "median": float(np.median(measured)) if measured else None,
                "max": max(measured) if measured else None,
                "failed_runs": failed_runs, "drivers": drivers}
    worst = sorted(checks.values(), key=lambda c: (c["yield"] if c["evaluated"] else 2.0,
                                                   c["plan"], c["check"]))
    return {"runs": len(rows), "lost": sum(1 for r in rows if r.get("lost")),
            "plans": list(plans.values()), "checks": worst}
