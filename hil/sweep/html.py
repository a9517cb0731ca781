"""The sweep's HTML page (yield tables, scatter plots as inline SVG) and its JUnit XML."""
from __future__ import annotations

import html
import math
import xml.etree.ElementTree as ET
from pathlib import Path

WORST_PLOTS = 6


def _pct(x) -> str:
    return "-" if x is None or (isinstance(x, float) and math.isnan(x)) else f"{100 * x:.1f} %"


def _num(x) -> str:
    return "-" if x is None else f"{x:.4g}"


def _unit_suffix(unit: str) -> str:
    """' A' after a number; nothing for a dimensionless value (unit "1")."""
    return "" if unit in ("1", "") else f" {unit}"


def range_labels(lo: float, hi: float) -> tuple[str, str]:
    """The texts of an axis' two ends, with the decimals the range needs (10.0400 and
    10.0412, not 10.04 twice); more if they would still read the same."""
    decimals = 0 if hi <= lo else max(0, 1 - math.floor(math.log10(hi - lo)))
    while True:
        a, b = f"{lo:.{decimals}f}", f"{hi:.{decimals}f}"
        if a != b or hi <= lo or decimals >= 15:
            return a, b
        decimals += 1


def spread_texts(lo, mid, hi) -> str:
    """'min / median / max': .4g, or the decimals their range needs when .4g would print
    different values the same (10.04 / 10.04 / 10.04)."""
    if lo is None or mid is None or hi is None:
        return f"{_num(lo)} / {_num(mid)} / {_num(hi)}"
    if hi <= lo or f"{lo:.4g}" != f"{hi:.4g}" or not (math.isfinite(lo) and math.isfinite(hi)):
        return f"{lo:.4g} / {mid:.4g} / {hi:.4g}"
    a, b = range_labels(lo, hi)
    decimals = len(a.partition(".")[2])
    return f"{a} / {mid:.{decimals}f} / {b}"


def _scatter(rows: list[dict], plan: str, check: str, param: str, unit: str) -> str:
    pts = []
    for r in rows:
        if r.get("lost") or r.get("plan") != plan:
            continue
        c = next((c for c in r["checks"] if c["name"] == check), None)
        x = r["params"].get(param)
        if c is None or c["measured"] is None or not isinstance(x, (int, float)) or isinstance(x, bool):
            continue
        pts.append((float(x), float(c["measured"]), c["outcome"] in ("PASS", "MARGINAL"), r["index"]))
    if not pts:
        return "<p>(no measured values)</p>"
    w, h, m = 420, 260, 48
    xs, ys = [p[0] for p in pts], [p[1] for p in pts]
    x0, x1 = min(xs), max(xs)
    y0, y1 = min(ys), max(ys)
    x1, y1 = (x1 if x1 > x0 else x0 + 1), (y1 if y1 > y0 else y0 + 1)
    sx = lambda v: m + (v - x0) / (x1 - x0) * (w - 1.5 * m)
    sy = lambda v: h - m + (v - y0) / (y1 - y0) * (-(h - 1.5 * m))
    dots = "".join(
        f'<circle cx="{sx(x):.1f}" cy="{sy(y):.1f}" r="3" fill="{"#2a7" if ok else "#d33"}">'
        f"<title>run {i}: {html.escape(param)} = {x:.5g}, {y:.5g}{html.escape(_unit_suffix(unit))}</title></circle>"
        for x, y, ok, i in pts)
    x0_text, x1_text = range_labels(x0, x1)
    y0_text, y1_text = range_labels(y0, y1)
    title = html.escape(check) + ("" if unit in ("1", "") else f" [{html.escape(unit)}]")
    return (f'<svg width="{w}" height="{h}" xmlns="http://www.w3.org/2000/svg" '
            f'style="background:#fafafa;border:1px solid #ddd">'
            f'<line x1="{m}" y1="{h - m}" x2="{w - m / 2}" y2="{h - m}" stroke="#888"/>'
            f'<line x1="{m}" y1="{m / 2}" x2="{m}" y2="{h - m}" stroke="#888"/>'
            f'<text x="{m}" y="{h - m + 14}" font-size="10">{x0_text}</text>'
            f'<text x="{w - m / 2}" y="{h - m + 14}" font-size="10" text-anchor="end">{x1_text}</text>'
            f'<text x="{w / 2}" y="{h - 8}" font-size="11" text-anchor="middle">{html.escape(param)}</text>'
            f'<text x="4" y="{h - m}" font-size="10" class="ytick">{y0_text}</text>'
            f'<text x="4" y="{m / 2 + 8}" font-size="10" class="ytick">{y1_text}</text>'
            f'<text x="{m + 4}" y="{m / 2 - 4}" font-size="11">{title}</text>'
            f"{dots}</svg>")


def write_html(sweep_info: dict, summary: dict, rows: list[dict], out: Path) -> Path:
    e = html.escape
    parts = [f"<!doctype html><html><head><meta charset='utf-8'><title>sweep {e(sweep_info['name'])}</title>"
             "<style>body{font-family:sans-serif;margin:2em}td,th{padding:2px 8px;border-bottom:1px solid #ddd;"
             "text-align:left}.bad{color:#c22}.fig{display:inline-block;margin:8px}</style></head><body>",
             f"<h1>Sweep {e(sweep_info['name'])}</h1>",
             f"<p>{summary['runs']} runs, seed {sweep_info['seed']}, {summary['lost']} lost "
             f"(no result). Yield = passed / runs with a verdict; 95 % Wilson intervals.</p>",
             "<h2>Plans</h2><table><tr><th>plan</th><th>runs</th><th>passed</th><th>yield</th>"
             "<th>95 % CI</th><th>outcomes</th></tr>"]
    for p in summary["plans"]:
        parts.append(f"<tr><td>{e(str(p['plan']))}</td><td>{p['runs']}</td><td>{p['passed']}</td>"
                     f"<td>{_pct(p['yield'])}</td><td>{_pct(p['ci_low'])} - {_pct(p['ci_high'])}</td>"
                     f"<td>{e(', '.join(f'{k} {v}' for k, v in sorted(p['outcomes'].items())))}</td></tr>")
    parts.append("</table><h2>Checks (worst first)</h2><table><tr><th>plan</th><th>check</th>"
                 "<th>evaluated</th><th>yield</th><th>95 % CI</th><th>min / median / max</th>"
                 "<th>strongest parameter (rho value, rho fail)</th><th>failed runs</th></tr>")
    for c in summary["checks"]:
        d = c["drivers"][0] if c["drivers"] else None
        drv = "-" if d is None else (f"{e(d['parameter'])} ({_num(d['rho_value'])}, {_num(d['rho_fail'])})")
        fr = ", ".join(map(str, c["failed_runs"][:12])) + (" ..." if len(c["failed_runs"]) > 12 else "")
        cls = " class='bad'" if c["failed"] else ""
        if c.get("finding"):
            counted, share = f"{c['measured_runs']} measured", "finding"
            interval = "(cannot fail)"
        else:
            counted, share = str(c["evaluated"]), _pct(c["yield"])
            interval = f"{_pct(c['ci_low'])} - {_pct(c['ci_high'])}"
        parts.append(f"<tr{cls}><td>{e(str(c['plan']))}</td><td>{e(c['check'])}</td><td>{counted}</td>"
                     f"<td>{share}</td><td>{interval}</td>"
                     f"<td>{spread_texts(c['min'], c['median'], c['max'])}{e(_unit_suffix(c['unit']))}</td>"
                     f"<td>{drv}</td><td>{fr}</td></tr>")
    parts.append("</table><h2>Worst checks against their strongest parameter</h2>"
                 "<p>green: the check passed in that run; red: it failed.</p>")
    for c in [c for c in summary["checks"] if c["drivers"]][:WORST_PLOTS]:
        parts.append(f"<div class='fig'>{_scatter(rows, c['plan'], c['check'], c['drivers'][0]['parameter'], c['unit'])}</div>")
    parts.append("</body></html>\n")
    path = out / "index.html"
    path.write_text("".join(parts))
    return path


def write_junit(sweep_info: dict, summary: dict, out: Path) -> Path:
    """One test case per (plan, check): failure when any run failed it, error when a run could
    not evaluate it; the message gives the yield and the failed runs."""
    suites = ET.Element("testsuites", name=f"sweep {sweep_info['name']}")
    by_plan: dict[str, list[dict]] = {}
    for c in summary["checks"]:
        by_plan.setdefault(str(c["plan"]), []).append(c)
    for plan, cs in by_plan.items():
        fails = sum(1 for c in cs if c["failed"])
        errors = sum(1 for c in cs if not c["failed"] and c["not_evaluated"].get("ERROR"))
        suite = ET.SubElement(suites, "testsuite", name=f"{sweep_info['name']}.{plan}",
                              tests=str(len(cs)), failures=str(fails), errors=str(errors))
        for c in cs:
            case = ET.SubElement(suite, "testcase", classname=f"sweep.{sweep_info['name']}.{plan}",
                                 name=c["check"])
            text = (f"yield {c['passed']}/{c['evaluated']} ({_pct(c['yield'])}, 95 % CI "
                    f"{_pct(c['ci_low'])} - {_pct(c['ci_high'])})")
            if c.get("finding"):
                text = (f"finding, measured in {c['measured_runs']} run(s): min / median / max "
                        f"{_num(c['min'])} / {_num(c['median'])} / {_num(c['max'])}{_unit_suffix(c['unit'])}")
            if c["failed"]:
                ET.SubElement(case, "failure", message=text).text = (
                    f"{text}; failed runs: {', '.join(map(str, c['failed_runs']))}")
            elif c["not_evaluated"].get("ERROR"):
                ET.SubElement(case, "error", message=f"{text}; not evaluated in "
                                                     f"{c['not_evaluated']['ERROR']} run(s)")
            else:
                ET.SubElement(case, "system-out").text = text
    path = out / "junit.xml"
    ET.ElementTree(suites).write(path, encoding="utf-8", xml_declaration=True)
    return path
