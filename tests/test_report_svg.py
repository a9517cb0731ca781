"""hil/reports/svg.py: ticks, the data-to-pixel mapping read back from the SVG text, gaps,
equal aspect, log bars and legend placement, each against values worked out by hand."""
from __future__ import annotations

import math
import re
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from hil.reports.svg import Figure, nice_ticks, polyline_points, tick_label


def tick_positions(svg: str) -> tuple[dict[str, float], dict[str, float]]:
    """x ticks {label: px} and y ticks {label: px} read from the tick marks' text."""
    xs = {m.group(2): float(m.group(1)) for m in
          re.finditer(r'<text x="([\d.]+)" y="[\d.]+" text-anchor="middle" font-size="10">([^<]+)<', svg)}
    ys = {m.group(2): float(m.group(1)) - 3.5 for m in
          re.finditer(r'<text x="[\d.]+" y="([\d.]+)" text-anchor="end" font-size="10">([^<]+)<', svg)}
    return xs, ys


@pytest.mark.parametrize("lo, hi, want", [
    (0.0, 1.0, [0.0, 0.2, 0.4, 0.6, 0.8, 1.0]),
    (-3.3, 3.3, [-3, -2, -1, 0, 1, 2, 3]),
    (1480.0, 3050.0, [1600, 1800, 2000, 2200, 2400, 2600, 2800, 3000]),
    (0.0, 7e-4, [0.0, 1e-4, 2e-4, 3e-4, 4e-4, 5e-4, 6e-4, 7e-4]),
])
def test_nice_ticks_are_round_steps_inside_the_range(lo, hi, want):
    got = nice_ticks(lo, hi)
    assert got == pytest.approx(want, abs=1e-12)


def test_tick_labels_carry_the_decimals_the_step_needs():
    assert [tick_label(v, 0.2) for v in (0.0, 0.2, 0.4, 0.6000000000000001)] == ["0", "0.2", "0.4", "0.6"]
    assert tick_label(2.5, 2.5) == "2.5" and tick_label(0.25, 0.25) == "0.25"
    assert tick_label(3000.0, 250.0) == "3000"
    assert tick_label(2e-4, 1e-4) == "0.0002" and tick_label(5e-5, 1e-5) == "5e-5"


def test_points_land_where_the_ticks_say():
    """A line through (0, 0), (0.5, 2), (1, 4): each point's pixel, interpolated from the
    drawn tick marks, is back at its data value."""
    fig = Figure()
    ax = fig.axes[0]
    ax.plot([0.0, 0.5, 1.0], [0.0, 2.0, 4.0])
    svg = fig.svg()
    ET.fromstring(svg)
    xs, ys = tick_positions(svg)
    (x_a, px_a), (x_b, px_b) = ((float(k), v) for k, v in list(xs.items())[:2])
    (y_a, py_a), (y_b, py_b) = ((float(k), v) for k, v in list(ys.items())[:2])
    points = polyline_points(svg)[0]
    for (px, py), (x, y) in zip(points, [(0.0, 0.0), (0.5, 2.0), (1.0, 4.0)]):
        assert x_a + (px - px_a) * (x_b - x_a) / (px_b - px_a) == pytest.approx(x, abs=0.005)
        assert y_a + (py - py_a) * (y_b - y_a) / (py_b - py_a) == pytest.approx(y, abs=0.02)
    assert points[0][1] > points[-1][1]          # y grows upwards on screen


def test_a_non_finite_value_breaks_the_line():
    fig = Figure()
    fig.axes[0].plot([0, 1, 2, 3, 4], [0, 1, math.nan, 3, 4])
    assert [len(p) for p in polyline_points(fig.svg())] == [2, 2]


def test_equal_aspect_gives_a_circle_equal_pixel_radii():
    fig = Figure(4.2, 4.0)
    ax = fig.axes[0]
    th = np.linspace(0, 2 * np.pi, 361)
    ax.plot(0.16 * np.cos(th), 0.16 * np.sin(th))
    ax.set_aspect("equal")
    pts = np.array(polyline_points(fig.svg())[0])
    width, height = np.ptp(pts[:, 0]), np.ptp(pts[:, 1])
    assert width == pytest.approx(height, rel=0.01)


def test_log_bars_span_decades_and_skip_zero():
    fig = Figure(ncols=2)
    ax = fig.axes[1]
    ax.bar([1, 2, 3], [100.0, 1.0, 0.0], color="#0969da")
    ax.set_yscale("log")
    svg = fig.svg()
    bars = re.findall(r'<rect x="[\d.]+" y="([\d.]+)" width="[\d.]+" height="([\d.]+)" fill="#0969da"/>', svg)
    assert len(bars) == 2                        # the zero harmonic has no bar on a log axis
    (y1, h1), (y2, h2) = ((float(a), float(b)) for a, b in bars)
    _, ys = tick_positions(svg)
    decade = ys["1"] - ys["10"]                  # pixels per decade from the drawn ticks
    assert h1 - h2 == pytest.approx(2 * decade, abs=0.2)


def test_legend_goes_to_the_corner_with_no_data():
    """A line along the top and one rising on the left: the legend, upper right by default,
    moves to the lower right, the one corner with nothing drawn."""
    fig = Figure()
    ax = fig.axes[0]
    x = np.linspace(0, 1, 200)
    ax.plot(x, 1.0 - 0.02 * x, label="near the top")
    ax.plot([0.0, 0.3], [0.0, 1.0], label="rising")
    ax.legend()
    svg = fig.svg()
    box = re.search(r'<rect x="([\d.]+)" y="([\d.]+)" width="([\d.]+)" height="(\d+)" '
                    r'fill="#ffffff" fill-opacity="0.85"', svg)
    lx, ly, lw, lh = (float(g) for g in box.groups())
    hidden = [(px, py) for line in polyline_points(svg) for px, py in line
              if lx <= px <= lx + lw and ly <= py <= ly + lh]
    assert hidden == []


def test_labels_are_escaped():
    fig = Figure()
    ax = fig.axes[0]
    ax.plot([0, 1], [0, 1], label="i_a < 5 & more")
    ax.legend()
    fig.suptitle("a <b>")
    ET.fromstring(fig.svg("alt \"quoted\""))     # well-formed despite <, & and quotes


@pytest.mark.parametrize("text", ["", "plain", "a & b < c > d \"e\" 'f'", "&amp; already", "<&>\"'" * 3,
                                  "ünïcode ✓ — µs", "\x00\n\t"])
def test_escape_is_html_escape(text):
    import html

    from hil.reports.svg import escape

    assert escape(text) == html.escape(text)


def _axis_tick_texts(svg: str) -> tuple[list[str], list[str]]:
    """The x and y tick labels of a one-axes figure: font-size 10 texts sharing a y (x ticks)
    or an x (y ticks)."""
    texts = re.findall(r'<text x="([\d.]+)" y="([\d.]+)" text-anchor="(\w+)" font-size="10">([^<]*)</text>', svg)
    xs = [t for _, _, anchor, t in texts if anchor == "middle"]
    ys = [t for _, _, anchor, t in texts if anchor == "end"]
    return xs, ys


@pytest.mark.parametrize("lo,hi", [(100000.0, 100050.0), (10.04, 10.0401), (-2.5e-4, -2.4999e-4),
                                   (0.0, 1e-9), (3.0, 4.0)])
def test_rendered_tick_labels_are_never_identical(lo, hi):
    """A step far below the values' magnitude (1e5 .. 1e5 + 50 read '1e5' on every tick)."""
    fig = Figure()
    ax = fig.axes[0]
    ax.plot(np.linspace(lo, hi, 50), np.linspace(lo, hi, 50))
    xs, ys = _axis_tick_texts(fig.svg())
    assert len(xs) >= 2 and len(ys) >= 2
    assert len(set(xs)) == len(xs) and len(set(ys)) == len(ys), (xs, ys)


def test_tick_labels_are_distinct_for_any_range():
    from hil.reports.svg import tick_labels

    rng = np.random.default_rng(7)
    for _ in range(500):
        centre = 10.0 ** rng.uniform(-8, 9) * rng.choice([-1, 1])
        width = abs(centre) * 10.0 ** rng.uniform(-9, 0.5)
        ticks = nice_ticks(centre - width, centre + width, int(rng.integers(2, 9)))
        texts = tick_labels(ticks)
        assert len(set(texts)) == len(texts), (ticks, texts)


def test_a_higher_zorder_line_is_drawn_later_and_the_legend_keeps_call_order():
    fig = Figure()
    ax = fig.axes[0]
    ax.plot([0, 1], [0, 1], label="truth", color="#000001", zorder=3)
    ax.plot([0, 1], [0, 1], label="estimate", color="#000002")
    ax.legend()
    svg = fig.svg()
    assert re.findall(r'<polyline [^>]*stroke="(#\w+)"', svg) == ["#000002", "#000001"]
    assert re.findall(r'font-size="9">([^<]*)<', svg) == ["truth", "estimate"]
