"""What a check figure and a plan figure draw (issue "a user's first hour", part 7): the
legend names every trace in the axis' unit, the plant's (true) traces are drawn above the
board's estimates, a limit line only where the check bounds the plotted signal itself, and a
statistic's own value named with the statistic; the sweep page's axis ends and units."""
from __future__ import annotations

import base64
import re

import numpy as np
import pytest

from hil.plans.format import PlotSpec
from hil.plans.limits import Limits
from hil.plans.outcome import CheckResult, Outcome
from hil.plans.signals import Signal, SignalSet
from hil.plans.units import convert
from hil.reports.html import check_figure, plan_figure

RED = "#cf222e"


def svg_of(b64: str) -> str:
    return base64.b64decode(b64).decode()


def legend(svg: str) -> list[str]:
    return re.findall(r'font-size="9">([^<]*)</text>', svg)


def ylabel(svg: str) -> str:
    return re.search(r'rotate\(-90\)" text-anchor="middle" font-size="11">([^<]*)<', svg).group(1)


def speed_signals() -> SignalSet:
    t = np.arange(0.0, 0.1, 1e-4)
    rpm = 1500.0 + 10.0 * np.sin(2 * np.pi * 50 * t)
    return SignalSet([Signal("plant.speed_rpm", t, rpm, "rpm"),
                      Signal("ctrl.speed_feedback_rad_s", t, convert(rpm, "rpm", "rad/s"), "rad/s"),
                      Signal("ctrl.torque_est_nm", t, np.ones_like(t), "Nm")])


def legend_units_agree(svg: str) -> None:
    """Every legend entry's unit (its name's suffix, or the unit in brackets) is the axis'."""
    axis = ylabel(svg)
    for label in legend(svg):
        said = re.search(r"\(([^()]*)\)$", label)
        assert not (label.endswith("_rad_s") and axis != "rad/s"), (label, axis)
        assert not (label.endswith("_rpm") and axis != "rpm"), (label, axis)
        assert said is None or said.group(1) == axis, (label, axis)


def test_a_rad_s_trace_on_an_rpm_axis_is_named_in_rpm():
    spec = PlotSpec("Speed", "time", ("plant.speed_rpm", "ctrl.speed_feedback_rad_s"), unit="rpm")
    svg = svg_of(plan_figure(spec, speed_signals(), {}, 0.1))
    assert ylabel(svg) == "rpm"
    legend_units_agree(svg)
    assert legend(svg) == ["plant.speed_rpm", "ctrl.speed_feedback (rpm)"]


@pytest.mark.parametrize("name,unit,expected", [
    ("ctrl.speed_feedback_rad_s", "rpm", "ctrl.speed_feedback (rpm)"),
    ("ctrl.speed_feedback_rad_s", "rad/s", "ctrl.speed_feedback_rad_s"),
    ("plant.i_a", "A", "plant.i_a (A)"),               # _a is the phase, not amperes
    ("plant.flux_mag_wb", "mWb", "plant.flux_mag (mWb)"),
    ("ctrl.state", "1", "ctrl.state")])
def test_legend_name(name, unit, expected):
    from hil.reports.html import legend_name

    assert legend_name(name, unit) == expected


def test_the_plants_trace_is_drawn_above_the_boards_estimate():
    t = np.arange(0.0, 0.01, 1e-4)
    signals = SignalSet([Signal("plant.torque_nm", t, np.ones_like(t), "Nm"),
                         Signal("ctrl.torque_est_nm", t, np.ones_like(t), "Nm")])
    spec = PlotSpec("Torque", "time", ("plant.torque_nm", "ctrl.torque_est_nm"), unit="Nm")
    svg = svg_of(plan_figure(spec, signals, {}, 0.01))
    colors = dict(re.findall(r'<path d="M[\d.]+ [\d.]+h16" stroke="(#\w+)"[^>]*/><text [^>]*>([^<]*)<', svg))
    plant = next(c for c, label in colors.items() if label.startswith("plant."))
    assert re.findall(r'<polyline [^>]*stroke="(#\w+)"', svg)[-1] == plant


def check(kind: str, details: dict, limits: Limits, measured: float, unit: str) -> CheckResult:
    return CheckResult("c", kind, Outcome.PASS, measured, unit, limits, "", (0.0, 0.1),
                       ("plant.torque_nm",), None, details)


def torque() -> SignalSet:
    t = np.arange(0.0, 0.12, 1e-4)
    return SignalSet([Signal("plant.torque_nm", t, 1.0 + 0.1 * np.sin(2 * np.pi * 500 * t), "Nm")])


@pytest.mark.parametrize("statistic,value", [("mean", 1.0), ("rms", 1.004)])
def test_a_statistic_check_draws_its_value_not_its_limits_over_the_trace(statistic, value):
    c = check("statistic", {"statistic": statistic, "measured_native": value, "native_unit": "Nm"},
              Limits("Nm", low=0.98, high=1.08), value, "Nm")
    svg = svg_of(check_figure(c, torque()))
    assert RED not in svg and "limit" not in legend(svg)
    named = {"mean": "mean = 1 Nm", "rms": "\u00b1RMS = 1.004 Nm"}[statistic]
    assert named in legend(svg)


def test_a_bound_check_draws_its_limit_lines():
    c = check("bound", {"measured_native": 1.1, "native_unit": "Nm"}, Limits("Nm", low=0.8, high=1.2),
              1.1, "Nm")
    svg = svg_of(check_figure(c, torque()))
    assert "limit" in legend(svg) and svg.count(f'stroke="{RED}"') >= 2


@pytest.mark.parametrize("measure,label", [("rms", "mean \u00b1 RMS ripple (0.07071 Nm)"),
                                           ("peak_to_peak", "peak-to-peak = 0.2 Nm")])
def test_a_ripple_check_draws_its_measure_named_as_it_is(measure, label):
    value = {"rms": 0.1 / np.sqrt(2), "peak_to_peak": 0.2}[measure]
    d = {"mean": 1.0, "min": 0.9, "max": 1.1, "measure": measure, "detrend": "mean",
         "measured_native": value, "native_unit": "Nm"}
    c = check("ripple", d, Limits("mNm", high=70), value * 1000, "mNm")
    svg = svg_of(check_figure(c, torque()))
    assert legend(svg)[-1] == label and "limit (p-p)" not in svg and RED not in svg


@pytest.mark.parametrize("lo,hi", [(10.04, 10.0412), (1500.25, 1500.46), (8e-4, 8.00002e-4),
                                   (0.0, 2000.0), (-3.0, -2.9999)])
def test_sweep_axis_ends_read_differently(lo, hi):
    from hil.sweep.html import range_labels

    a, b = range_labels(lo, hi)
    assert a != b and float(a) == pytest.approx(lo, abs=hi - lo) and float(b) == pytest.approx(hi, abs=hi - lo)


def test_sweep_spread_keeps_the_decimals_its_range_needs():
    from hil.sweep.html import spread_texts

    assert spread_texts(10.0401, 10.0405, 10.0412) == "10.0401 / 10.0405 / 10.0412"
    assert spread_texts(2.0, 2.0, 2.0) == "2 / 2 / 2"
    assert spread_texts(None, None, None) == "- / - / -"
