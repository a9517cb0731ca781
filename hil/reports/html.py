"""Reports of a run: JUnit XML, a self-contained HTML page, and the JSON run record.

`write_reports` writes, for one plan, into its output directory:

- ``junit.xml``: one testsuite per plan, one testcase per check (FAIL ->
  <failure>, ERROR -> <error>, not reached -> <skipped>, MARGINAL passes with
  a note); a plan that ended in ERROR, TIMEOUT or ABORTED adds an error
  testcase carrying the reason. Valid against the Jenkins junit-10.xsd
  (tests/data/junit-10.xsd).
- ``report.html``: one file with inline CSS and SVG plots as base64 data
  URIs (hil/reports/svg.py, drawn in milliseconds): the outcome and its cause,
  the verdicts (measured values against limits), the plan's description
  folded below them, the figures the plan's ``plots:`` section asks for, and
  a plot of each check's window (limit lines where the check bounds the
  plotted signal, the named statistic where it bounds a statistic).
- ``result.json``: PlanResult.to_json(), plain data for other tools.

`write_summary` writes the multi-plan index.html and a combined junit.xml.
"""
from __future__ import annotations

import base64
import json
import math
import os
import re
import xml.etree.ElementTree as ET
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path

import numpy as np

from hil.plans.limits import Limits
from hil.plans.outcome import CheckResult, Outcome, PlanResult
from hil.plans.signals import SignalSet
from hil.plans.units import compatible, convert, is_angle
from hil.reports.svg import Figure, escape

MAX_PLOT_POINTS = 4000
_COLORS = {"PASS": "#1a7f37", "MARGINAL": "#9a6700", "FAIL": "#cf222e", "ERROR": "#8250df",
           "TIMEOUT": "#bc4c00", "ABORTED": "#57606a", "SKIPPED": "#6e7781", "INFO": "#0969da"}
ROLE_TITLES = {"acceptance": "Acceptance checks (limits derived before the first run)",
               "regression": "Regression bounds (taken from a measurement; they still fail the plan)",
               "finding": "Findings (measured and recorded; they cannot fail the plan)"}


def slug(name: str) -> str:
    """A file-system and URL friendly form of a plan name."""
    return re.sub(r"[^A-Za-z0-9_.-]+", "-", name).strip("-").lower() or "plan"


# --------------------------------------------------------------------------- #
# JUnit XML                                                                    #
# --------------------------------------------------------------------------- #

_XML_BAD = re.compile("[\x00-\x08\x0b\x0c\x0e-\x1f]")


def _x(text: str) -> str:
    return _XML_BAD.sub("?", str(text))


def _time(seconds: float) -> str:
    return f"{max(seconds, 0.0):.3f}" if math.isfinite(seconds) else "0.000"


def suite_name(result: PlanResult) -> str:
    """'plan [profile]' (the plan name alone when it ran on no named profile)."""
    return f"{result.plan_name} [{result.profile}]" if result.profile else result.plan_name


def junit_suite(result: PlanResult) -> ET.Element:
    """One <testsuite> for a plan on one profile; a regression or finding check's testcase name
    says so, and a finding never carries a <failure>."""
    classname = f"hil.{slug(result.plan_name)}"
    if result.profile:
        classname += f".{slug(result.profile.replace('/', '-'))}"
    cases: list[ET.Element] = []
    failures = errors = skipped = 0
    for c in result.checks:
        label = c.name if c.role == "acceptance" else f"{c.name} [{c.role}]"
        case = ET.Element("testcase", name=_x(label), classname=classname, time="0.000")
        detail = _x(_check_text(c))
        if c.outcome is Outcome.FAIL:
            failures += 1
            ET.SubElement(case, "failure", type="FAIL", message=_x(c.message)).text = detail
        elif c.outcome is Outcome.ERROR:
            errors += 1
            ET.SubElement(case, "error", type="ERROR", message=_x(c.message)).text = detail
        elif c.outcome is Outcome.SKIPPED:
            skipped += 1
            ET.SubElement(case, "skipped", message=_x(c.message))
        ET.SubElement(case, "system-out").text = detail
        cases.append(case)
    if result.outcome in (Outcome.ERROR, Outcome.TIMEOUT, Outcome.ABORTED):
        errors += 1
        case = ET.Element("testcase", name=f"plan {result.outcome.value.lower()}",
                          classname=classname, time=_time(result.wall_duration_s))
        ET.SubElement(case, "error", type=result.outcome.value,
                      message=_x(result.reason)).text = _x(
            f"{result.source}: plan '{result.plan_name}' ended {result.outcome.value}: {result.reason}")
        cases.append(case)
    suite = ET.Element("testsuite", name=_x(suite_name(result)), tests=str(len(cases)),
                       failures=str(failures), errors=str(errors), skipped=str(skipped),
                       time=_time(result.wall_duration_s), timestamp=_x(result.started_at),
                       hostname=_x(_hostname()), file=_x(result.source))
    props = ET.SubElement(suite, "properties")
    for key, value in (("outcome", result.outcome.value), ("reason", result.reason),
                       ("profile", result.profile),
                       ("source", result.source), ("link", result.link), ("mode", result.mode),
                       ("sim_duration_s", f"{result.sim_duration_s:.6f}"),
                       ("log", result.log_path or "")):
        ET.SubElement(props, "property", name=key, value=_x(value))
    suite.extend(cases)
    return suite


def _hostname() -> str:
    """socket.gethostname(), which on POSIX is uname's node name: read from os.uname() there,
    so writing a report does not import socket (its enums cost ~5 ms of a short run)."""
    uname = getattr(os, "uname", None)
    if uname is not None:
        return uname().nodename
    import socket

    return socket.gethostname()


def junit_xml(results: Iterable[PlanResult]) -> str:
    """A <testsuites> document for one or more plans."""
    results = list(results)
    root = ET.Element("testsuites", name="hil-bench")
    totals = {"tests": 0, "failures": 0, "errors": 0}
    wall = 0.0
    for r in results:
        suite = junit_suite(r)
        for key in totals:
            totals[key] += int(suite.get(key))
        wall += r.wall_duration_s
        root.append(suite)
    for key, value in totals.items():
        root.set(key, str(value))
    root.set("time", _time(wall))
    ET.indent(root)
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n"


def _check_text(c: CheckResult) -> str:
    lines = [f"{c.outcome.value}: {c.message}"]
    if c.role != "acceptance":
        lines.append(f"role: {c.role}")
    if c.note:
        lines.append(f"note: {c.note}")
    if c.window is not None:
        lines.append(f"window: {c.window[0]:.6f} .. {c.window[1]:.6f} s")
    if c.signals:
        lines.append(f"signals: {', '.join(c.signals)}")
    if c.line is not None:
        lines.append(f"plan line: {c.line}")
    return "\n".join(lines)


# --------------------------------------------------------------------------- #
# Plots                                                                        #
# --------------------------------------------------------------------------- #

def _decimate(t: np.ndarray, y: np.ndarray, max_points: int = MAX_PLOT_POINTS) -> tuple[np.ndarray, np.ndarray]:
    """Min/max decimation: keeps the ripple envelope a plain stride would alias away."""
    n = len(t)
    if n <= max_points:
        return t, y
    buckets = max_points // 2
    size = n // buckets
    m = buckets * size
    tb = t[:m].reshape(buckets, size)
    yb = y[:m].reshape(buckets, size)
    imin, imax = yb.argmin(axis=1), yb.argmax(axis=1)
    first = np.minimum(imin, imax)
    second = np.maximum(imin, imax)
    rows = np.arange(buckets)
    tt = np.column_stack([tb[rows, first], tb[rows, second]]).ravel()
    yy = np.column_stack([yb[rows, first], yb[rows, second]]).ravel()
    return np.concatenate([tt, t[m:]]), np.concatenate([yy, y[m:]])


def _encoded(fig: Figure, alt: str) -> str:
    """The figure as a base64 SVG document for an <img> data URI."""
    return base64.b64encode(fig.svg(alt).encode("utf-8")).decode("ascii")


def _hline_limits(ax, limits: Limits | None, unit: str) -> None:
    """Limit lines (solid) and the marginal band (dashed) on an axis in `unit`."""
    if limits is None or not compatible(limits.unit, unit):
        return
    lim = limits.in_unit(unit)
    for bound, sign in ((lim.low, 1.0), (lim.high, -1.0)):
        if bound is None:
            continue
        ax.axhline(bound, color="#cf222e", lw=1.0, ls="-", label="limit")
        if lim.marginal:
            ax.axhline(bound + sign * lim.marginal, color="#9a6700", lw=0.8, ls="--",
                       label="marginal")


#: Unit suffixes of signal names (plant.speed_rpm, ctrl.speed_feedback_rad_s), longest first.
_NAME_UNITS = (("_rad_s", "rad/s"), ("_deg_s", "deg/s"), ("_mwb", "mWb"), ("_rpm", "rpm"),
               ("_nm", "Nm"), ("_wb", "Wb"), ("_deg", "deg"), ("_rad", "rad"), ("_hz", "Hz"))


def _name_suffix(name: str) -> tuple[str, str] | None:
    """(suffix, unit) of a signal name that ends in a unit, else None."""
    lower = name.lower()
    return next(((suffix, u) for suffix, u in _NAME_UNITS if lower.endswith(suffix)), None)


def name_unit(name: str) -> str | None:
    """The unit a signal's name says it is in (its suffix), or None."""
    found = _name_suffix(name)
    return found[1] if found else None


def legend_name(name: str, unit: str) -> str:
    """A trace's legend entry on an axis in `unit`: the name when its suffix already says
    that unit, else the name without a suffix that says another unit, with the unit drawn
    (ctrl.speed_feedback_rad_s converted to rpm is "ctrl.speed_feedback (rpm)")."""
    found = _name_suffix(name)
    if found is not None and found[1] == unit:
        return name
    if found is not None:
        name = name[: -len(found[0])]
    return name if unit == "1" else f"{name} ({unit})"


def _zorder(name: str) -> float:
    """The plant's signals (the truth) are drawn above the board's estimates and references."""
    return 3.0 if name.startswith("plant.") else 2.0


def _value_text(value: float, unit: str) -> str:
    return f"{value:.4g}" + ("" if unit == "1" else f" {unit}")


def _statistic_marks(ax, d: Mapping, signal_unit: str, unit: str) -> None:
    """A statistic's value where it reads on the trace, named: the mean as a line, the RMS
    and max |x| as lines at +- the value; the others (std, peak-to-peak) are not drawn. The
    limits bound the statistic, not the trace: they are in the verdict table, not drawn."""
    name = d.get("statistic")
    value = d.get("measured_native")
    if value is None or not math.isfinite(value) or not compatible(d.get("native_unit", signal_unit), unit):
        return
    v = float(convert(value, d.get("native_unit", signal_unit), unit))
    if name == "mean":
        ax.axhline(v, color="#57606a", lw=1.0, ls="--", label=f"mean = {_value_text(v, unit)}")
    elif name == "rms":
        ax.axhline(v, color="#57606a", lw=1.0, ls="--", label=f"\u00b1RMS = {_value_text(v, unit)}")
        ax.axhline(-v, color="#57606a", lw=1.0, ls="--")
    elif name == "max_abs":
        ax.axhline(v, color="#57606a", lw=1.0, ls="--", label=f"\u00b1max |x| = {_value_text(v, unit)}")
        ax.axhline(-v, color="#57606a", lw=1.0, ls="--")


def _ripple_marks(ax, d: Mapping, signal_unit: str, unit: str) -> None:
    """A ripple check's measured value on the trace: peak-to-peak as the band from the
    window's minimum to its maximum (what it measures with the mean removed), RMS as the
    band mean +- RMS; named with the measure. The limit is on the measure, in the table."""
    if not compatible(signal_unit, unit):
        return
    value = d.get("measured_native")
    if value is None or not math.isfinite(value):
        return
    v = float(convert(value, d.get("native_unit", signal_unit), unit))
    mean = float(convert(d["mean"], signal_unit, unit))
    if d.get("measure") == "rms":
        ax.axhspan(mean - v, mean + v, color="#8250df", alpha=0.12,
                   label=f"mean \u00b1 RMS ripple ({_value_text(v, unit)})")
    elif d.get("measure", "peak_to_peak") == "peak_to_peak" and d.get("detrend", "mean") == "mean":
        lo, hi = (float(convert(d[k], signal_unit, unit)) for k in ("min", "max"))
        ax.axhspan(lo, hi, color="#8250df", alpha=0.12,
                   label=f"peak-to-peak = {_value_text(v, unit)}")


def _plot_window(c: CheckResult) -> tuple[float, float]:
    """The check's window with 10 % of context either side."""
    t0, t1 = c.window
    pad = 0.1 * (t1 - t0)
    return t0 - pad, t1 + pad


def check_figure(c: CheckResult, signals: SignalSet) -> str | None:
    """A base64 SVG of a check's window with its limits, or None when there is nothing to plot."""
    if c.window is None or not c.signals or any(n not in signals for n in c.signals):
        return None
    if c.kind == "circularity":
        return _locus_check_figure(c, signals)
    a, b = _plot_window(c)
    main = signals[c.signals[0]]
    unit = main.unit
    fig = Figure(ncols=2 if c.kind == "thd" else 1)
    ax = fig.axes[0]
    for name in c.signals:
        s = signals[name]
        if not compatible(s.unit, unit):
            continue
        w = s.window(a, b).to_unit(unit)
        t, y = _decimate(w.t_s, w.values)
        ax.plot(t, y, lw=0.8, label=legend_name(name, unit), zorder=_zorder(name))
    ax.axvspan(c.window[0], c.window[1], color="#0969da", alpha=0.06, label="window")
    d = c.details
    t0 = c.window[0]
    if c.kind in ("final_value", "bound") or (c.kind == "statistic"
                                              and d.get("statistic") in ("min", "max")):
        _hline_limits(ax, c.limits, unit)
    elif c.kind == "statistic":
        _statistic_marks(ax, d, main.unit, unit)
    elif c.kind in ("settling_time", "rise_time", "overshoot") and "target" in d:
        su = d.get("signal_unit", unit)
        target = float(convert(d["target"], su, unit))
        ax.axhline(target, color="#57606a", lw=0.8, ls=":", label="target")
        if c.kind == "settling_time" and "band" in d:
            band = abs(float(convert(d["band"], su, unit)))
            ax.axhspan(target - band, target + band, color="#1a7f37", alpha=0.12, label="band")
            if c.measured is not None and math.isfinite(c.measured):
                ax.axvline(t0 + convert(c.measured, c.unit, "s"), color="#1a7f37", lw=1.0,
                           label="settled")
            if c.limits is not None and c.limits.high is not None:
                ax.axvline(t0 + convert(c.limits.high, c.limits.unit, "s"), color="#cf222e",
                           lw=1.0, ls="--", label="limit")
        if c.kind == "rise_time" and "t_from_s" in d:
            initial = float(convert(d["initial"], su, unit))
            for pct, key in ((d["from_pct"], "t_from_s"), (d["to_pct"], "t_to_s")):
                ax.axhline(initial + (target - initial) * pct / 100.0, color="#57606a", lw=0.6, ls=":")
                if math.isfinite(d[key]):
                    ax.axvline(d[key], color="#1a7f37", lw=1.0, label="crossings")
        if c.kind == "overshoot" and c.limits is not None and c.limits.high is not None:
            initial = float(convert(d["initial"], su, unit))
            peak_ok = target + (target - initial) * convert(c.limits.high, c.limits.unit, "%") / 100
            ax.axhline(peak_ok, color="#cf222e", lw=1.0, label="limit")
    elif c.kind == "envelope" and "_tube" in d:
        tt, lo, hi = d["_tube"]
        ax.fill_between(tt, lo, hi, color="#1a7f37", alpha=0.15, step="mid", label="envelope")
    elif c.kind == "ripple" and "mean" in d:
        _ripple_marks(ax, d, main.unit, unit)
    ax.set_xlabel("t (s)")
    ax.set_ylabel(unit)
    ax.grid(True, lw=0.3)
    ax.legend()
    if c.kind == "thd" and "harmonic_amplitudes" in d:
        ax2 = fig.axes[1]
        amps = np.asarray(d["harmonic_amplitudes"], dtype=float)
        ax2.bar(np.arange(1, len(amps) + 1), amps / amps[0] * 100.0, color="#0969da")
        ax2.set_yscale("log")
        ax2.set_xlabel("harmonic")
        ax2.set_ylabel("% of fundamental")
        ax2.grid(True, lw=0.3)
    fig.suptitle(f"{c.name} [{c.outcome.value}]", color=_COLORS.get(c.outcome.value))
    return _encoded(fig, c.name)


def _locus_check_figure(c: CheckResult, signals: SignalSet) -> str:
    x = signals[c.signals[0]].window(*c.window)
    y = signals[c.signals[1]].window(*c.window).to_unit(x.unit)
    fig = Figure(4.2, 4.0)
    ax = fig.axes[0]
    xs, ys = x.values, y.resampled(x.t_s)
    ax.plot(xs, ys, lw=0.6, label="locus")
    d = c.details
    if "r_mean" in d:
        th = np.linspace(0, 2 * np.pi, 361)
        cx, cy = d.get("centre_x", 0.0), d.get("centre_y", 0.0)
        r = d["r_mean"]
        ax.plot(cx + r * np.cos(th), cy + r * np.sin(th), color="#57606a", ls=":", lw=0.8,
                label="mean circle")
        if (d.get("measure", "peak_to_peak") == "peak_to_peak" and "r_min" in d and "r_max" in d
                and c.measured is not None and math.isfinite(c.measured)):
            # the check bounds the spread (max - min radius) / mean radius, not the radius:
            # the measured extremes are drawn, named with the spread; the limit is in the table
            spread = _value_text(c.measured, c.unit)
            for rr in (d["r_min"], d["r_max"]):
                ax.plot(cx + rr * np.cos(th), cy + rr * np.sin(th), color="#8250df", lw=0.8,
                        ls="--", label=f"min / max radius (spread {spread})")
    ax.set_aspect("equal")
    ax.set_xlabel(f"{x.name} ({x.unit})")
    ax.set_ylabel(f"{y.name} ({y.unit})")
    ax.grid(True, lw=0.3)
    ax.legend()
    fig.suptitle(f"{c.name} [{c.outcome.value}]", color=_COLORS.get(c.outcome.value))
    return _encoded(fig, c.name)


def plan_figure(spec, signals: SignalSet, marks: Mapping[str, float], end_s: float) -> str | None:
    """A base64 SVG for one entry of a plan's ``plots:`` section (hil.plans.format.PlotSpec)."""
    present = [n for n in spec.signals if n in signals]
    if not present or (spec.type == "xy" and len(present) < 2):
        return None
    if spec.window is not None:
        try:
            a, b = spec.window.resolve(marks, end_s)
        except KeyError:
            a, b = 0.0, end_s
    else:
        a, b = 0.0, end_s
    if spec.type == "xy":
        x = signals[spec.signals[0]].window(a, b)
        y = signals[spec.signals[1]].window(a, b).to_unit(x.unit)
        fig = Figure(4.2, 4.0)
        ax = fig.axes[0]
        ax.plot(x.values, y.resampled(x.t_s), lw=0.6)
        ax.set_aspect("equal")
        ax.set_xlabel(f"{x.name} ({x.unit})")
        ax.set_ylabel(f"{y.name} ({y.unit})")
    else:
        fig = Figure()
        ax = fig.axes[0]
        units = set()
        for name in present:
            s = signals[name].window(a, b)
            if spec.unit is not None:
                s = s.to_unit(spec.unit)
            elif is_angle(s.unit):
                s = s.to_unit("deg")
            units.add(s.unit)
            t, y = _decimate(s.t_s, s.values)
            ax.plot(t, y, lw=0.8, label=legend_name(name, s.unit), zorder=_zorder(name))
        for mark, t_mark in marks.items():
            if a <= t_mark <= b and mark != "start":
                ax.axvline(t_mark, color="#57606a", lw=0.6, ls=":")
                ax.annotate_mark(mark, t_mark)
        ax.set_xlabel("t (s)")
        ax.set_ylabel(", ".join(sorted(units)))
        if len(present) > 1:
            ax.legend()
    ax.grid(True, lw=0.3)
    fig.suptitle(spec.title)
    return _encoded(fig, spec.title)


# --------------------------------------------------------------------------- #
# HTML                                                                         #
# --------------------------------------------------------------------------- #

_CSS = """
body{font-family:system-ui,-apple-system,Segoe UI,Helvetica,Arial,sans-serif;margin:1.5em auto;
max-width:1100px;color:#1f2328;padding:0 1em}
h1{font-size:1.5em;margin-bottom:.2em}h2{font-size:1.15em;margin-top:1.6em;border-bottom:1px solid #d0d7de}
h3{font-size:1em;margin-bottom:.3em}
table{border-collapse:collapse;width:100%;font-size:.88em}td,th{border:1px solid #d0d7de;padding:3px 6px;
text-align:left;vertical-align:top}th{background:#f6f8fa}td.num{text-align:right;font-variant-numeric:tabular-nums}
.badge{display:inline-block;padding:1px 8px;border-radius:10px;color:#fff;font-weight:600;font-size:.85em}
pre{background:#f6f8fa;padding:.6em;white-space:pre-wrap;font-size:.85em}
img{max-width:100%;border:1px solid #d0d7de;margin:.3em 0}
.meta td:first-child{width:12em;color:#57606a}.muted{color:#57606a;font-size:.85em}
"""


def _badge(outcome: str) -> str:
    return f'<span class="badge" style="background:{_COLORS.get(outcome, "#57606a")}">{escape(outcome)}</span>'


def _fmt(value: float | None) -> str:
    if value is None:
        return "-"
    if math.isinf(value):
        return "inf" if value > 0 else "-inf"
    return f"{value:.5g}"


def _unit_text(unit: str) -> str:
    return "" if unit == "1" else f" {unit}"


def _derivation_html(d: dict) -> str:
    """A formula with its inputs: the formula, then 'name = value unit' per input."""
    items = []
    for i in d.get("inputs", ()):
        items.append(f"<li>{escape(i['name'])} = {float(i['value']):.6g}{escape(_unit_text(i['unit']))}</li>")
    inputs = f"<ul class=\"inputs\">{''.join(items)}</ul>" if items else ""
    return f"<code class=\"formula\">{escape(d['formula'])}</code>{inputs}"


def _formulas_html(formulas: dict) -> str:
    """Under a check's limits: each bound's formula, its value and its inputs."""
    if not formulas:
        return ""
    rows = []
    for bound, d in formulas.items():
        value = f"{float(d['value']):.6g}{_unit_text(d['unit'])}"
        rows.append(f"<div class=\"derivation\">{escape(bound)} = {escape(value)}: "
                    f"{_derivation_html(d)}</div>")
    return f"<div class=\"formulas\">{''.join(rows)}</div>"


def _img(b64: str | None, alt: str) -> str:
    if b64 is None:
        return '<p class="muted">(no plot: the data is not available)</p>'
    return f'<img alt="{escape(alt)}" src="data:image/svg+xml;base64,{b64}">'


def html_report(result: PlanResult, signals: SignalSet, plots: Sequence = ()) -> str:
    """The self-contained HTML page of one plan's run."""
    e = escape
    end_s = signals.end_s if len(signals) else result.sim_duration_s
    counts = result.counts()
    parts = [f"<!DOCTYPE html><html lang=\"en\"><head><meta charset=\"utf-8\">"
             f"<title>{e(suite_name(result))} - {e(result.outcome.value)}</title><style>{_CSS}</style></head><body>",
             f"<h1>{e(result.plan_name)} {_badge(result.outcome.value)}</h1>",
             f"<p>profile: <b>{e(result.profile or 'paper')}</b></p>",
             _cause_html(result)]
    meta = [("source", result.source), ("profile", result.profile or "-"), ("link / mode", f"{result.link} / {result.mode}"),
            ("simulated time", f"{result.sim_duration_s:.4f} s"),
            ("wall time", f"{result.wall_duration_s:.2f} s"),
            ("started / ended", f"{result.started_at} / {result.ended_at}"),
            ("log", result.log_path or "-"),
            ("checks", ", ".join(f"{n} {k}" for k, n in counts.items() if n))]
    parts.append('<table class="meta">' + "".join(f"<tr><td>{e(k)}</td><td>{e(str(v))}</td></tr>"
                                                  for k, v in meta) + "</table>")
    constants = result.extra.get("constants") or {}
    if constants:
        parts.append("<h2>Constants</h2><table><tr><th>name</th><th>value</th><th>formula and inputs</th></tr>"
                     + "".join(f"<tr><td>{e(name)}</td><td class=\"num\">{e(_fmt(d['value']))} {e(d['unit'])}</td>"
                               f"<td>{_derivation_html(d)}</td></tr>" for name, d in constants.items())
                     + "</table>")

    parts.append("<h2>Verdicts</h2>")
    for role, title in ROLE_TITLES.items():
        rows = [(i, c) for i, c in enumerate(result.checks, 1) if c.role == role]
        if not rows:
            continue
        claim = "claim" if role == "finding" else "limits"
        parts.append(f"<h3>{e(title)}</h3><table><tr><th>#</th><th>check</th><th>kind</th>"
                     f"<th>measured</th><th>{claim}</th><th>outcome</th><th>message</th>"
                     + ("<th>note</th>" if role != "acceptance" else "") + "</tr>")
        for i, c in rows:
            unit = "" if c.unit == "1" else f" {c.unit}"
            limits = c.limits.describe() if c.limits is not None else "-"
            parts.append(f"<tr><td>{i}</td><td><a href=\"#check-{i}\">{e(c.name)}</a></td><td>{e(c.kind)}</td>"
                         f"<td class=\"num\">{e(_fmt(c.measured))}{e(unit)}</td><td>{e(limits)}{_formulas_html(c.formulas)}</td>"
                         f"<td>{_badge(c.outcome.value)}</td><td>{e(c.message)}</td>"
                         + (f"<td>{e(c.note)}</td>" if role != "acceptance" else "") + "</tr>")
        parts.append("</table>")
    if result.description:
        # the plan's derivation of its limits: long, and read after the verdicts, on demand
        parts.append(f'<details class="description"><summary>Plan description (how its limits '
                     f'were derived)</summary><pre>{e(result.description)}</pre></details>')

    if plots:
        parts.append("<h2>Figures</h2>")
        for spec in plots:
            parts.append(f"<h3>{e(spec.title)}</h3>{_img(plan_figure(spec, signals, result.marks, end_s), spec.title)}")

    parts.append("<h2>Check windows</h2>")
    for i, c in enumerate(result.checks, 1):
        where = f"line {c.line}" if c.line is not None else ""
        window = (f"{c.window[0]:.4f} .. {c.window[1]:.4f} s" if c.window is not None else "")
        parts.append(f'<h3 id="check-{i}">{i}. {e(c.name)} {_badge(c.outcome.value)}</h3>'
                     f'<p class="muted">{e(c.kind)}; {e(", ".join(c.signals))}; {e(window)} {e(where)}</p>')
        if c.outcome is not Outcome.SKIPPED and c.plot:
            parts.append(_img(check_figure(c, signals), c.name))
        elif c.outcome is Outcome.SKIPPED and c.plot and c.signals:
            # never reached: its signals as recorded up to the moment the run ended
            parts.append(_img(recorded_figure(c, signals, result.marks, end_s), c.name))

    if result.steps:
        parts.append("<h2>Steps</h2><table><tr><th>#</th><th>line</th><th>step</th><th>outcome</th>"
                     "<th>start (s)</th><th>end (s)</th><th>message</th></tr>")
        for s in result.steps:
            parts.append(f"<tr><td>{s.index + 1}</td><td>{s.line or ''}</td><td>{e(s.kind)}</td>"
                         f"<td>{_badge(s.outcome.value)}</td><td class=\"num\">{_fmt(s.start_s)}</td>"
                         f"<td class=\"num\">{_fmt(s.end_s)}</td><td>{e(s.message)}</td></tr>")
        parts.append("</table>")
    if result.marks:
        parts.append("<h2>Marks</h2><p>" + ", ".join(f"{e(k)} = {v:.6f} s" for k, v in result.marks.items())
                     + "</p>")
    if result.extra.get("board_states"):
        parts.append(_board_states_html(result.extra["board_states"]))
    parts.append('<p class="muted">hil-bench report</p></body></html>\n')
    return "".join(parts)


def _cause_html(result: PlanResult) -> str:
    """The reason at the top; for a plan that did not pass, as its cause, with the board's
    FAULTs named and the moment the run ended."""
    e = escape
    if result.outcome in (Outcome.PASS,):
        return f"<p>{e(result.reason)}</p>"
    color = _COLORS.get(result.outcome.value, "#57606a")
    rows = [f"<p><b>Cause</b>: {e(result.reason)}</p>"]
    faults = result.extra.get("board_faults") or []
    if faults:
        items = "".join(f"<li>{e(str(f.get('text') or _fault_words(f)))}</li>" for f in faults[:5])
        more = f"<li>and {len(faults) - 5} more</li>" if len(faults) > 5 else ""
        rows.append(f"<p>Board FAULTs ({len(faults)}):</p><ul>{items}{more}</ul>")
    rows.append(f'<p class="muted">the run ended at t = {result.sim_duration_s:.6g} s simulated; '
                f'checks not reached are SKIPPED, their signals drawn up to that moment</p>')
    return (f'<div class="cause" style="border-left:4px solid {color};padding:.2em .8em;'
            f'background:#f6f8fa">' + "".join(rows) + "</div>")


def _fault_words(fault: Mapping) -> str:
    return (f"period {fault.get('period')}: board FAULT {fault.get('code')} "
            f"{fault.get('name', '')}, value {fault.get('value')}")


def recorded_figure(c: CheckResult, signals: SignalSet, marks: Mapping[str, float],
                    end_s: float) -> str | None:
    """A check never reached: its signals from the start to the end of the recording."""
    from types import SimpleNamespace

    spec = SimpleNamespace(title=f"{c.name} [SKIPPED]: recorded up to t = {end_s:.6g} s",
                           signals=tuple(c.signals), type="time", window=None, unit=None)
    return plan_figure(spec, signals, marks, end_s)


def _board_states_html(changes: Sequence[Mapping]) -> str:
    """The board's STATUS state changes (SPEC 9.4), the moments it became ready flagged."""
    rows = "".join(f"<tr><td class=\"num\">{float(c['t_s']):.6f}</td><td class=\"num\">{int(c['period'])}</td>"
                   f"<td>{escape(str(c['name']))}{' (ready)' if c.get('ready') else ''}</td>"
                   f"<td class=\"num\">{int(c.get('fault_code', 0))}</td></tr>" for c in changes)
    return ("<h2>Board states</h2><table><tr><th>t (s)</th><th>period</th><th>state</th>"
            "<th>fault code</th></tr>" + rows + "</table>")


# --------------------------------------------------------------------------- #
# Files                                                                        #
# --------------------------------------------------------------------------- #

def _plots_for(result: PlanResult, plan) -> Sequence:
    if plan is not None:
        return plan.plots
    source = Path(result.source)
    if source.is_file():
        from hil.plans.format import load_plan
        from configfile.source import ConfigError

        try:
            return load_plan(source).plots
        except ConfigError:
            return ()
    return ()


def write_reports(result: PlanResult, signals: SignalSet, out_dir: str | Path,
                  plan=None) -> dict[str, Path]:
    """Writes junit.xml, report.html and result.json into out_dir; returns their paths.

    plan: the hil.plans.format.Plan that ran, for its ``plots:`` section (default:
    reloaded from result.source).
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = {"junit": out / "junit.xml", "html": out / "report.html", "json": out / "result.json"}
    paths["junit"].write_text(junit_xml([result]), encoding="utf-8")
    paths["html"].write_text(html_report(result, signals, _plots_for(result, plan)), encoding="utf-8")
    paths["json"].write_text(json.dumps(result.to_json(), indent=2) + "\n", encoding="utf-8")
    return paths


def write_summary(entries: Sequence[tuple[PlanResult, Mapping[str, Path]]],
                  out_dir: str | Path) -> dict[str, Path]:
    """index.html (one row per plan, linking its report) and a combined junit.xml."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    e = escape
    results = [r for r, _ in entries]
    rows = []
    profiles: list[str] = []
    for r, _ in entries:
        if r.profile not in profiles:
            profiles.append(r.profile)
    grid: dict[str, dict[str, str]] = {}
    apart: list[str] = []
    for r, paths in entries:
        counts = r.counts()
        link = paths.get("html")
        href = ""
        if link is not None:
            try:
                href = Path(link).resolve().relative_to(out.resolve()).as_posix()
            except ValueError:
                href = Path(link).resolve().as_uri()
        total = sum(counts.values())
        passed = counts["PASS"] + counts["MARGINAL"]
        name = f'<a href="{e(href)}">{e(r.plan_name)}</a>' if href else e(r.plan_name)
        total -= counts.get("INFO", 0)
        rows.append(f"<tr><td>{name}</td><td>{e(r.profile or '-')}</td><td>{_badge(r.outcome.value)}</td>"
                    f"<td class=\"num\">{passed}/{total}</td><td class=\"num\">{counts['MARGINAL']}</td>"
                    f"<td class=\"num\">{counts.get('INFO', 0)}</td>"
                    f"<td class=\"num\">{r.sim_duration_s:.3f}</td><td class=\"num\">{r.wall_duration_s:.2f}</td>"
                    f"<td>{e(r.reason)}</td></tr>")
        cell = f"{_badge(r.outcome.value)} {passed}/{total}"
        grid.setdefault(r.plan_name, {})[r.profile] = (f'<a href="{e(href)}">{cell}</a>' if href else cell)
        for c in r.checks:
            if c.role == "acceptance":
                continue
            unit = "" if c.unit == "1" else f" {c.unit}"
            apart.append(f"<tr><td>{e(c.role)}</td><td>{e(r.plan_name)}</td><td>{e(r.profile or '-')}</td>"
                         f"<td>{e(c.name)}</td><td class=\"num\">{e(_fmt(c.measured))}{e(unit)}</td>"
                         f"<td>{e(c.limits.describe() if c.limits is not None else '-')}</td>"
                         f"<td>{_badge(c.outcome.value)}</td><td>{e(c.note)}</td></tr>")
    worst = _worst([r.outcome for r in results])
    side = ("<h2>Plans by profile</h2><table><tr><th>plan</th>"
            + "".join(f"<th>{e(p or '-')}</th>" for p in profiles) + "</tr>"
            + "".join(f"<tr><td>{e(plan)}</td>" + "".join(f"<td>{cells.get(p, '')}</td>" for p in profiles)
                      + "</tr>" for plan, cells in grid.items()) + "</table>")
    apart_html = ("" if not apart else
                  "<h2>Regression bounds and findings</h2><p class=\"muted\">Regression bounds come "
                  "from a measurement and still fail a plan; findings are recorded and cannot.</p>"
                  "<table><tr><th>role</th><th>plan</th><th>profile</th><th>check</th><th>measured</th>"
                  "<th>limits / claim</th><th>outcome</th><th>note</th></tr>" + "".join(apart) + "</table>")
    page = (f"<!DOCTYPE html><html lang=\"en\"><head><meta charset=\"utf-8\"><title>hil-bench run - "
            f"{e(worst)}</title><style>{_CSS}</style></head><body><h1>hil-bench run {_badge(worst)}</h1>"
            f"<p>{len(results)} run(s) of {len(grid)} plan(s) on {len(profiles)} profile(s)</p>" + side
            + "<h2>Runs</h2><table><tr><th>plan</th><th>profile</th><th>outcome</th><th>checks passed</th>"
            f"<th>marginal</th><th>findings</th><th>simulated (s)</th><th>wall (s)</th><th>reason</th></tr>"
            + "".join(rows) + "</table>" + apart_html + "</body></html>\n")
    paths = {"html": out / "index.html", "junit": out / "junit.xml", "json": out / "summary.json"}
    paths["html"].write_text(page, encoding="utf-8")
    paths["junit"].write_text(junit_xml(results), encoding="utf-8")
    paths["json"].write_text(json.dumps({"outcome": worst, "plans": [
        {"plan": r.plan_name, "profile": r.profile, "outcome": r.outcome.value, "reason": r.reason,
         "reports": {k: str(v) for k, v in p.items()}} for r, p in entries]}, indent=2) + "\n",
        encoding="utf-8")
    return paths


def _worst(outcomes: Iterable[Outcome]) -> str:
    order = [Outcome.PASS, Outcome.FAIL, Outcome.TIMEOUT, Outcome.ERROR, Outcome.ABORTED]
    worst = Outcome.PASS
    for o in outcomes:
        if o in order and order.index(o) > order.index(worst):
            worst = o
    return worst.value


__all__ = ["write_reports", "write_summary", "junit_xml", "junit_suite", "html_report",
           "check_figure", "plan_figure", "slug"]
