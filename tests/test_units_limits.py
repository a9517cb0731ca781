"""Engineering units and structured limits."""
from __future__ import annotations

import math

import numpy as np
import pytest

from hil.plans.limits import Limits
from hil.plans.outcome import Outcome
from hil.plans.units import Quantity, UnitError, canonical, compatible, convert, wrap_angle


@pytest.mark.parametrize("value, src, dst, expected", [
    (3000.0, "rpm", "rad/s", 100 * math.pi),
    (100 * math.pi, "rad/s", "rpm", 3000.0),
    (150.0, "ms", "s", 0.15),
    (50.0, "us", "ms", 0.05),
    (180.0, "deg", "rad", math.pi),
    (2.0, "Nm", "mNm", 2000.0),
    (92.8, "mWb", "Wb", 0.0928),
    (250.0, "mA", "A", 0.25),
    (5.0, "%", "1", 0.05),
    (4.8, "mH", "H", 4.8e-3),
    (1.0, "kHz", "Hz", 1000.0),
])
def test_conversions(value, src, dst, expected):
    assert convert(value, src, dst) == pytest.approx(expected, rel=1e-12)


def test_conversion_of_arrays_and_aliases():
    out = convert(np.array([60.0, 120.0]), "r/min", "rad_s")
    assert np.allclose(out, [2 * math.pi, 4 * math.pi])
    assert canonical("µs") == "us" and canonical("") == "1" and canonical("N*m") == "Nm"


def test_incompatible_and_unknown_units_are_clear_errors():
    with pytest.raises(UnitError, match=r"cannot convert rpm \(angular velocity\) to A \(current\)"):
        convert(1.0, "rpm", "A")
    with pytest.raises(UnitError, match="unknown unit 'furlong'; known units: 1, %"):
        convert(1.0, "furlong", "m")
    # Hz is a frequency, not a speed: the 2 pi and electrical/mechanical choice is the plan's.
    assert not compatible("Hz", "rad/s")


def test_wrap_angle_into_half_open_interval():
    assert wrap_angle(math.pi) == pytest.approx(math.pi)
    assert wrap_angle(-math.pi) == pytest.approx(math.pi)
    assert wrap_angle(3 * math.pi / 2) == pytest.approx(-math.pi / 2)
    assert wrap_angle(370.0, "deg") == pytest.approx(10.0)


def test_quantity():
    q = Quantity(3000, "rpm")
    assert q.to("rad/s") == pytest.approx(100 * math.pi)
    assert str(q) == "3000 rpm"


@pytest.mark.parametrize("value, expected", [
    (100.0, Outcome.PASS), (135.0, Outcome.PASS), (140.0, Outcome.MARGINAL),
    (150.0, Outcome.MARGINAL), (150.01, Outcome.FAIL), (math.inf, Outcome.FAIL),
])
def test_upper_limit_with_marginal_band(value, expected):
    lim = Limits("ms", high=150.0, marginal=15.0)
    assert lim.judge(value) is expected


def test_two_sided_limits_and_conversion_of_the_measurement():
    lim = Limits("rpm", low=2985.0, high=3015.0, marginal=5.0)
    assert lim.judge(100 * math.pi, "rad/s") is Outcome.PASS            # 3000 rpm
    assert lim.judge(2988.0) is Outcome.MARGINAL
    assert lim.judge(2980.0) is Outcome.FAIL
    assert lim.judge(-math.inf) is Outcome.FAIL


def test_outside_comparison():
    lim = Limits("A", low=-1.0, high=1.0, comparison="outside", marginal=0.5)
    assert lim.judge(0.0) is Outcome.FAIL
    assert lim.judge(1.2) is Outcome.MARGINAL
    assert lim.judge(-2.0) is Outcome.PASS


def test_limits_reject_nonsense():
    with pytest.raises(ValueError, match="at least one of low, high"):
        Limits("rpm")
    with pytest.raises(ValueError, match="low .* is above high"):
        Limits("rpm", low=2.0, high=1.0)
    with pytest.raises(ValueError, match="needs both low and high"):
        Limits("rpm", low=1.0, comparison="outside")
    with pytest.raises(UnitError):
        Limits("parsec", high=1.0)
    with pytest.raises(ValueError, match="NaN"):
        Limits("s", high=1.0).judge(math.nan)


def test_limits_in_another_unit_and_description():
    lim = Limits("rpm", low=2940.0, high=3060.0, marginal=10.0)
    rad = lim.in_unit("rad/s")
    assert rad.low == pytest.approx(98 * math.pi) and rad.high == pytest.approx(102 * math.pi)
    assert lim.describe() == "2940 .. 3060 rpm (marginal within 10 rpm)"
    assert Limits("%", high=5).describe() == "<= 5 %"
    assert Limits.from_json(lim.to_json()) == lim
