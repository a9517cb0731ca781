"""The bench's line for a board FAULT names the fault code and, for NON_FINITE (SPEC.md 9.6),
the quantity its value codes; values that code nothing are said to be unknown."""
from __future__ import annotations

import math

import pytest

from hil.session.bench_session import _fault_text
from protocol.messages import Fault, FaultCode, NonFiniteQuantity

PERIOD_S = 50e-6


def test_overcurrent_keeps_its_unit():
    assert _fault_text(Fault(5001, int(FaultCode.OVERCURRENT), 21.3), PERIOD_S) == (
        "period 5001 (t = 0.25005 s): board FAULT 1 OVERCURRENT, value 21.3 A")


@pytest.mark.parametrize("quantity", list(NonFiniteQuantity))
def test_non_finite_names_the_quantity(quantity):
    text = _fault_text(Fault(7, 6, float(quantity.value)), PERIOD_S)
    assert text.endswith(f"board FAULT 6 NON_FINITE, value {quantity.value} ({quantity.name})")


@pytest.mark.parametrize("value", [math.nan, math.inf, 2.5, 9.0, -1.0])
def test_non_finite_with_a_value_that_codes_nothing(value):
    assert _fault_text(Fault(7, 6, value), PERIOD_S).endswith("(unknown quantity)")


def test_stall_is_named_with_its_seconds():
    """Code 7 (SPEC 9.6): a locked rotor reads STALL with the seconds without a commutation
    event, not ENCODER_LOSS."""
    assert _fault_text(Fault(5001, int(FaultCode.STALL), 0.05), PERIOD_S) == (
        "period 5001 (t = 0.25005 s): board FAULT 7 STALL, value 0.05 s")


def test_an_unknown_code_is_named_unknown():
    assert "board FAULT 8 UNKNOWN, value 1" in _fault_text(Fault(7, 8, 1.0), PERIOD_S)
