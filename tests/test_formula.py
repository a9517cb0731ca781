"""The limit-formula language (hil.plans.formula): whitelist, units, errors, inputs."""
from __future__ import annotations

import math

import pytest

from hil.plans.formula import FormulaError, evaluate, names_in, parse

VALUES = {
    "motor.inertia_kgm2": (8.0e-4, "kgm^2"),
    "board.torque_limit_nm": (2.0, "Nm"),
    "board.speed_ki_nm_per_rad": (0.79, "Nm/rad"),
    "timing.control_period_s": (50e-6, "s"),
    "delta_speed": (1500.0, "rpm"),
    "zero_torque": (0.0, "Nm"),
    "dc_link.source_voltage_v": (70.0, "V"),
    "motor.inductance_q_h": (4.8e-3, "H"),
    "motor.flux_linkage_wb": (0.0928, "Wb"),
}


def test_the_briefs_example_against_a_hand_computation():
    d = evaluate("1.2 * motor.inertia_kgm2 * delta_speed / board.torque_limit_nm "
                 "+ 2 * timing.control_period_s", VALUES, "ms")
    # 1500 rpm = 157.0796 rad/s; 1.2 * 8e-4 * 157.0796 / 2 = 0.0753982 s; + 0.1 ms
    assert d.value == pytest.approx((1.2 * 8e-4 * 1500 * 2 * math.pi / 60 / 2 + 2 * 50e-6) * 1e3)
    assert d.unit == "ms"
    assert [i.name for i in d.inputs] == ["motor.inertia_kgm2", "delta_speed",
                                          "board.torque_limit_nm", "timing.control_period_s"]
    assert d.inputs[1].value == 1500.0 and d.inputs[1].unit == "rpm"


def test_compound_units_reduce_to_the_limits_unit():
    # sqrt(Ki / J) is an angular velocity; (2/3 Vdc) T / Ls * 1.5 psi is a torque
    w = evaluate("sqrt(board.speed_ki_nm_per_rad / motor.inertia_kgm2)", VALUES, "rad/s")
    assert w.value == pytest.approx(math.sqrt(0.79 / 8e-4))
    t = evaluate("2/3 * dc_link.source_voltage_v * timing.control_period_s / "
                 "motor.inductance_q_h * 1.5 * motor.flux_linkage_wb", VALUES, "Nm")
    assert t.value == pytest.approx(2 / 3 * 70 * 50e-6 / 4.8e-3 * 1.5 * 0.0928)
    assert evaluate("max(board.torque_limit_nm, 3 * zero_torque) - abs(-zero_torque)",
                    VALUES, "mNm").value == pytest.approx(2000.0)
    assert evaluate("pi ** 2", VALUES, "1").value == pytest.approx(math.pi ** 2)


@pytest.mark.parametrize("text, unit, message", [
    ("motor.inertia_kgm2 * delta_speed", "ms", "which is not ms"),
    ("board.torque_limit_nm + timing.control_period_s", "Nm", "adds"),
    ("board.torque_limt_nm", "Nm", "did you mean 'board.torque_limit_nm'"),
    ("board.torque_limit_nm / zero_torque", "1", "division by zero"),
    ("board.torque_limit_nm ** delta_speed", "Nm", "has a unit"),
    ("exp(1000)", "1", "overflows"),
    ("sqrt(-1 * board.torque_limit_nm / board.torque_limit_nm)", "1", "negative"),
])
def test_errors_name_the_problem(text, unit, message):
    with pytest.raises(FormulaError, match=message.replace("(", r"\(").replace(")", r"\)")):
        evaluate(text, VALUES, unit)


@pytest.mark.parametrize("text", [
    "__import__('os').system('true')", "open('x')", "board.torque_limit_nm.__class__",
    "(1).real", "[1, 2]", "1 if 1 else 2", "1 < 2", "'text'", "lambda: 1", "x[0]",
    "True", "1 // 2", "1 % 2", "sqrt(x=1)", "f'{1}'",
])
def test_anything_outside_the_whitelist_is_refused(text):
    with pytest.raises(FormulaError):
        parse(text)


def test_long_or_deep_formulas_are_refused_not_crashed():
    for text in ["1+" * 249 + "1", "(" * 240 + "1" + ")" * 240, "-" * 499 + "1"]:
        try:
            evaluate(text, VALUES, "1")
        except FormulaError:
            pass                                    # refused with a message: fine
    with pytest.raises(FormulaError, match="at most 500"):
        parse("1+" * 300 + "1")
    with pytest.raises(FormulaError):
        evaluate("1e308 * 1e308", VALUES, "1")      # not finite
    with pytest.raises(FormulaError):
        evaluate("(0 - 8) ** (1 / 3)", VALUES, "1")  # no real value


def test_names_in_lists_dotted_names_once():
    assert sorted(names_in("a.b.c * a.b.c + sqrt(d) + pi")) == ["a.b.c", "d", "pi"]
