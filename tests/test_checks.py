"""Every check kind against an analytic answer on a synthetic signal."""
from __future__ import annotations

import math

import numpy as np
import pytest

from hil.plans import checks
from hil.plans.checks import CheckError, evaluate_check
from hil.plans.outcome import CheckResult, Outcome
from hil.plans.format import parse_plan
from hil.plans.signals import Signal, SignalSet

DT = 50e-6  # the paper's control period: one sample per period


def _t(duration_s: float, t0: float = 0.0) -> np.ndarray:
    return t0 + DT * np.arange(int(round(duration_s / DT)) + 1)


def _first_order(t, tau, t_step=0.0, y0=0.0, y1=1.0):
    return np.where(t < t_step, y0, y1 + (y0 - y1) * np.exp(-(t - t_step) / tau))


def _second_order(t, zeta, wn):
    wd = wn * math.sqrt(1 - zeta * zeta)
    phi = math.acos(zeta)
    return 1 - np.exp(-zeta * wn * t) / math.sqrt(1 - zeta * zeta) * np.sin(wd * t + phi)


def _check(yaml_body: str, prefix: str = "") -> tuple:
    """Parses a one-check plan; returns (plan, check step)."""
    text = f"name: t\nsteps:\n{prefix}  - run: {{duration_s: 1.0}}\n  - check:\n" + "\n".join(
        "      " + line for line in yaml_body.strip().splitlines()) + "\n"
    plan = parse_plan(text, "synthetic.yaml")
    return plan, plan.checks[-1]


# ----------------------------------------------------------- layer 1: numbers

def test_settling_time_of_first_order_step_is_tau_ln_50():
    tau = 0.02
    t = _t(0.3)
    y = _first_order(t, tau)
    ts = checks.settling_time(t, y, target=1.0, band=0.02)
    assert ts == pytest.approx(tau * math.log(50), abs=DT / 10)


def test_settling_time_inf_when_never_settles_and_zero_when_always_inside():
    t = _t(0.05)
    assert checks.settling_time(t, _first_order(t, 0.1), 1.0, 0.02) == math.inf
    assert checks.settling_time(t, np.full(len(t), 1.001), 1.0, 0.02) == 0.0


def test_rise_time_of_first_order_is_tau_ln_9_in_both_directions():
    tau = 0.01
    t = _t(0.2)
    up = _first_order(t, tau, y0=1500.0, y1=3000.0)
    down = _first_order(t, tau, y0=3000.0, y1=1500.0)
    assert checks.rise_time(t, up, 1500.0, 3000.0) == pytest.approx(tau * math.log(9), abs=DT / 10)
    assert checks.rise_time(t, down, 3000.0, 1500.0) == pytest.approx(tau * math.log(9), abs=DT / 10)


def test_overshoot_of_second_order_step():
    zeta, wn = 0.5, 200.0
    t = _t(0.2)
    y = 1500.0 + 1500.0 * _second_order(t, zeta, wn)
    expected = 100 * math.exp(-zeta * math.pi / math.sqrt(1 - zeta ** 2))   # 16.30 %
    assert checks.overshoot_percent(y, 1500.0, 3000.0) == pytest.approx(expected, rel=1e-3)
    assert checks.overshoot_percent(_first_order(t, 0.01), 0.0, 1.0) == 0.0


def test_zero_step_is_an_error_not_a_number():
    with pytest.raises(CheckError, match="zero step"):
        checks.overshoot_percent(np.ones(10), 1.0, 1.0)


def test_thd_of_sine_with_known_harmonics():
    t = _t(0.1)[:-1]
    f0 = 50.0
    y = (7.0 * np.sin(2 * np.pi * f0 * t) + 0.7 * np.sin(2 * np.pi * 3 * f0 * t + 0.3)
         + 0.35 * np.sin(2 * np.pi * 5 * f0 * t))
    expected = math.hypot(0.1, 0.05) * 100          # 11.18 %
    thd, d = checks.thd_percent(t, y, fundamental_hz=f0)
    assert thd == pytest.approx(expected, rel=1e-6)
    assert d["fundamental_amplitude"] == pytest.approx(7.0, rel=1e-6)
    thd_est, d_est = checks.thd_percent(t, y)       # fundamental found from the spectrum
    assert d_est["fundamental_hz"] == pytest.approx(f0, rel=2e-3)
    assert thd_est == pytest.approx(expected, rel=1e-2)


def test_thd_total_counts_non_harmonic_ripple_that_harmonic_thd_ignores():
    t = _t(0.1)[:-1]
    # 1230 Hz: a whole number of cycles in the record but not a harmonic of 50 Hz, like
    # the switching ripple of a hysteresis drive.
    y = 5.0 * np.sin(2 * np.pi * 50 * t) + 0.5 * np.sin(2 * np.pi * 1230.0 * t)
    harmonic, _ = checks.thd_percent(t, y, 50.0, method="harmonics")
    total, _ = checks.thd_percent(t, y, 50.0, method="total")
    assert total == pytest.approx(10.0, rel=2e-3)   # 0.5 / 5 in RMS terms
    assert harmonic < 1e-6


def test_lag_of_delayed_copy():
    rng = np.random.default_rng(1)
    t = _t(0.2)
    white = rng.standard_normal(len(t) + 400)
    kernel = np.exp(-np.arange(200) / 40.0)
    smooth = np.convolve(white, kernel, mode="same")
    delay_samples = 37                               # 1.85 ms
    ref = smooth[200:200 + len(t)]
    y = smooth[200 - delay_samples:200 - delay_samples + len(t)]
    lag, peak = checks.lag_s(t, y, ref, max_lag_s=0.005)
    assert lag == pytest.approx(delay_samples * DT, abs=DT / 4)
    assert peak > 0.99
    lead, _ = checks.lag_s(t, ref, y, max_lag_s=0.005)
    assert lead == pytest.approx(-delay_samples * DT, abs=DT / 4)


def test_lag_of_low_pass_filtered_ramp_is_its_time_constant():
    """A first-order filter lags a ramp by exactly its time constant in steady state."""
    tau = 1 / (2 * np.pi * 30.0)                    # 30 Hz cut-off: 5.3 ms
    t = _t(0.15)
    truth = np.minimum(t, 0.1) * 1000.0              # a torque-limited speed ramp, then flat
    filt = np.empty_like(truth)
    a = DT / (tau + DT)
    acc = truth[0]
    for i, x in enumerate(truth):
        acc += a * (x - acc)
        filt[i] = acc
    lag, _ = checks.lag_s(t, filt, truth, max_lag_s=0.02)
    assert lag == pytest.approx(tau, rel=0.1)


def test_lag_refuses_a_peak_at_the_search_edge():
    t = _t(0.1)
    ref = np.sin(2 * np.pi * 20 * t)
    y = np.sin(2 * np.pi * 20 * (t - 0.01))
    with pytest.raises(CheckError, match="edge of the search range"):
        checks.lag_s(t, y, ref, max_lag_s=0.002)


def test_ripple_peak_to_peak_and_rms_of_a_triangle():
    t = _t(0.02)
    tri = 0.1 + 0.002 * (2 * np.abs(((t * 500) % 1.0) - 0.5) * 2 - 1)   # +-2 mWb at 500 Hz
    assert checks.ripple(t, tri, "peak_to_peak") == pytest.approx(0.004, rel=1e-3)
    assert checks.ripple(t, tri, "rms") == pytest.approx(0.002 / math.sqrt(3), rel=1e-2)
    drifting = tri + 0.5 * t
    assert checks.ripple(t, drifting, "peak_to_peak", detrend="linear") == pytest.approx(0.004, rel=1e-2)


def test_circularity_of_a_circle_with_sixfold_ripple_and_of_an_offset_circle():
    th = np.linspace(0, 2 * np.pi, 5000, endpoint=False)
    r = 0.0928 * (1 + 0.05 * np.sin(6 * th))
    value, d = checks.circularity_percent(r * np.cos(th), r * np.sin(th))
    assert value == pytest.approx(10.0, rel=1e-3)
    assert d["r_mean"] == pytest.approx(0.0928, rel=1e-6)
    x, y = 0.1 * np.cos(th) + 0.01, 0.1 * np.sin(th)
    about_origin, _ = checks.circularity_percent(x, y, centre="origin")
    about_fit, d_fit = checks.circularity_percent(x, y, centre="fit")
    assert about_origin == pytest.approx(20.0, rel=1e-2)     # (0.11 - 0.09) / 0.1
    assert about_fit == pytest.approx(0.0, abs=1e-9)
    assert d_fit["centre_x"] == pytest.approx(0.01, abs=1e-12)


def test_envelope_time_tolerance_admits_a_late_step_and_value_tolerance_a_small_error():
    t = _t(0.1)
    ref = np.where(t >= 0.05, 3000.0, 1500.0)
    late = np.where(t >= 0.053, 3000.0, 1500.0) + 10.0
    exc, lo, hi = checks.envelope_excursion(t, late, t, ref, tolerance=20.0, time_tolerance_s=0.005)
    assert exc == 0.0
    exc_tight, _, _ = checks.envelope_excursion(t, late, t, ref, tolerance=20.0, time_tolerance_s=0.001)
    # While the step is 3 ms late the signal (1510) is below the tube's floor (3000 - 20).
    assert exc_tight == pytest.approx(3000.0 - 20.0 - 1510.0)
    exc_value, _, _ = checks.envelope_excursion(t, late, t, ref, tolerance=5.0, time_tolerance_s=0.005)
    assert exc_value == pytest.approx(5.0)


def test_running_extreme_matches_brute_force():
    rng = np.random.default_rng(3)
    x = rng.standard_normal(257)
    for m in (0, 1, 5, 40, 300):
        fast = checks._running_extreme(x, m, np.maximum)
        slow = np.array([x[max(0, i - m):i + m + 1].max() for i in range(len(x))])
        assert np.array_equal(fast, slow)


def test_angle_error_wraps():
    truth = np.array([3.1, -3.1, 0.0])
    est = np.array([-3.1, 3.1, 0.1])
    err = checks.error_between(est, truth, "rad")
    assert np.allclose(err, [2 * np.pi - 6.2, -(2 * np.pi - 6.2), 0.1])


# --------------------------------------------- layer 2: evaluate_check on plans

def _speed_step_signals():
    t = _t(0.5)
    speed = _first_order(t, 0.02, t_step=0.1, y0=1500.0, y1=3000.0)
    ref = np.where(t >= 0.1, 3000.0, 1500.0)
    return SignalSet([
        Signal("plant.speed_rpm", t, speed, "rpm"),
        Signal("plant.speed_rad_s", t, speed * 2 * np.pi / 60, "rad/s"),
        Signal("cmd.speed_ref_rpm", t, ref, "rpm"),
    ])


def test_settling_check_converts_to_limit_unit_and_judges():
    sig = _speed_step_signals()
    _, spec = _check("""
name: speed settles
kind: settling_time
signal: plant.speed_rad_s
window: {from: step, duration_s: 0.35}
target: {value: 3000, unit: rpm}
initial: {value: 1500, unit: rpm}
band_pct: 2
limits: {high: 150, marginal: 20, unit: ms}
""", prefix="  - mark: step\n")
    r = evaluate_check(spec, sig, {"step": 0.1})
    assert r.outcome is Outcome.PASS
    assert r.unit == "ms"
    assert r.measured == pytest.approx(0.02 * math.log(50) * 1e3, abs=0.01)
    assert r.window == pytest.approx((0.1, 0.45))
    assert r.signals == ("plant.speed_rad_s",)


def test_impossible_limit_fails_with_the_measured_value():
    sig = _speed_step_signals()
    _, spec = _check("""
name: impossible settling
kind: settling_time
signal: plant.speed_rpm
window: {from: step}
target: {value: 3000, unit: rpm}
initial: {value: 1500, unit: rpm}
limits: {high: 1, unit: ms}
""", prefix="  - mark: step\n")
    r = evaluate_check(spec, sig, {"step": 0.1})
    assert r.outcome is Outcome.FAIL
    assert r.measured == pytest.approx(78.24, abs=0.05)
    assert "measured 78.2" in r.message and "<= 1 ms" in r.message


def test_marginal_band():
    sig = _speed_step_signals()
    _, spec = _check("""
name: close call
kind: final_value
signal: plant.speed_rpm
average_s: 0.01
limits: {low: 2990, high: 3003, marginal: 5, unit: rpm}
""")
    r = evaluate_check(spec, sig, {})
    assert r.outcome is Outcome.MARGINAL
    assert r.measured == pytest.approx(3000.0, abs=1e-3)


def test_bound_reports_the_extreme_closest_to_a_limit():
    sig = _speed_step_signals()
    _, spec = _check("""
name: speed range
kind: bound
signal: plant.speed_rpm
limits: {low: 1000, high: 3010, unit: rpm}
""")
    r = evaluate_check(spec, sig, {})
    assert r.outcome is Outcome.PASS
    assert r.measured == pytest.approx(3000.0, abs=1e-3)
    assert r.details["min"] == pytest.approx(1500.0)


def test_steady_state_error_with_a_reference_signal_in_another_unit():
    sig = _speed_step_signals()
    _, spec = _check("""
name: error
kind: steady_state_error
signal: plant.speed_rad_s
reference: cmd.speed_ref_rpm
window: {from: now, offset_s: -0.05}
limits: {low: -1, high: 1, unit: rpm}
""")
    r = evaluate_check(spec, sig, {}, now_s=0.5)
    assert r.outcome is Outcome.PASS
    assert abs(r.measured) < 1e-3


def test_rms_error_of_angles_in_degrees_handles_wrap():
    t = _t(0.04)
    theta = np.angle(np.exp(1j * 2 * np.pi * 50 * t))          # wrapped truth
    est = np.angle(np.exp(1j * (2 * np.pi * 50 * t + np.deg2rad(3.0))))
    sig = SignalSet([Signal("plant.theta_e_rad", t, theta, "rad"),
                     Signal("ctrl.rotor_pos_ekf_rad", t, est, "rad")])
    _, spec = _check("""
name: position error
kind: rms_error
signal: ctrl.rotor_pos_ekf_rad
reference: plant.theta_e_rad
limits: {high: 5, unit: deg}
""")
    r = evaluate_check(spec, sig, {})
    assert r.unit == "deg"
    assert r.measured == pytest.approx(3.0, abs=1e-6)


def test_envelope_check_defaults_to_nothing_outside():
    sig = _speed_step_signals()
    _, ok = _check("""
name: follows
kind: envelope
signal: plant.speed_rpm
reference: cmd.speed_ref_rpm
tolerance: {value: 30, unit: rpm}
time_tolerance_s: 0.1
""")
    assert evaluate_check(ok, sig, {}).outcome is Outcome.PASS
    _, tight = _check("""
name: follows tightly
kind: envelope
signal: plant.speed_rpm
reference: cmd.speed_ref_rpm
tolerance: {value: 30, unit: rpm}
time_tolerance_s: 0.01
""")
    r = evaluate_check(tight, sig, {})
    assert r.outcome is Outcome.FAIL and r.measured > 100


def test_lag_and_compare_checks():
    t = _t(0.3)
    truth = 1500 + np.clip((t - 0.05) / 0.063, 0, 1) * 1500
    lpf = np.interp(t - 0.005, t, truth)
    ekf = np.interp(t - 0.0005, t, truth)
    sig = SignalSet([Signal("plant.speed_rpm", t, truth, "rpm"),
                     Signal("ctrl.speed_lpf_rad_s", t, lpf * np.pi / 30, "rad/s"),
                     Signal("ctrl.speed_ekf_rad_s", t, ekf * np.pi / 30, "rad/s")])
    plan = parse_plan("""
name: lags
steps:
  - run: {duration_s: 0.3}
  - check: {name: lpf lag, kind: lag, signal: ctrl.speed_lpf_rad_s, reference: plant.speed_rpm,
            max_lag_s: 0.02, limits: {low: 3, high: 8, unit: ms}}
  - check: {name: ekf lag, kind: lag, signal: ctrl.speed_ekf_rad_s, reference: plant.speed_rpm,
            limits: {high: 1, unit: ms}}
  - check: {name: ekf lags less, kind: compare, a: ekf lag, b: lpf lag, operation: difference,
            limits: {high: -2, unit: ms}}
  - check: {name: ekf lag ratio, kind: compare, a: ekf lag, b: lpf lag, limits: {high: 0.5, unit: "1"}}
""", "lags.yaml")
    results: dict[str, CheckResult] = {}
    for c in plan.checks:
        results[c.name] = evaluate_check(c, sig, {}, results=results)
    assert results["lpf lag"].measured == pytest.approx(5.0, abs=0.1)
    assert results["ekf lag"].measured == pytest.approx(0.5, abs=0.1)
    assert results["ekf lags less"].measured == pytest.approx(-4.5, abs=0.2)
    assert results["ekf lag ratio"].measured == pytest.approx(0.1, abs=0.03)
    assert all(r.outcome is Outcome.PASS for r in results.values())


def test_thd_and_circularity_and_ripple_checks_through_the_registry():
    t = _t(0.1)
    th = 2 * np.pi * 50 * t
    psi_a, psi_b = 0.0928 * np.cos(th), 0.0928 * np.sin(th)
    ia = 7.0 * np.sin(th) + 0.7 * np.sin(3 * th)
    torque = 1.0 + 0.1 * np.sign(np.sin(2 * np.pi * 2000 * t))
    sig = SignalSet([Signal("plant.psi_alpha", t, psi_a, "Wb"), Signal("plant.psi_beta", t, psi_b, "Wb"),
                     Signal("plant.i_a", t, ia, "A"), Signal("plant.torque_nm", t, torque, "Nm")])
    plan = parse_plan("""
name: shape
steps:
  - run: {duration_s: 0.1}
  - check: {name: thd, kind: thd, signal: plant.i_a, fundamental_hz: 50, limits: {high: 12, unit: "%"}}
  - check: {name: round, kind: circularity, alpha: plant.psi_alpha, beta: plant.psi_beta,
            limits: {high: 1, unit: "%"}}
  - check: {name: torque ripple, kind: ripple, signal: plant.torque_nm, limits: {high: 250, unit: mNm}}
""", "shape.yaml")
    r = {c.name: evaluate_check(c, sig, {}) for c in plan.checks}
    assert r["thd"].measured == pytest.approx(10.0, rel=1e-3) and r["thd"].outcome is Outcome.PASS
    assert r["round"].measured == pytest.approx(0.0, abs=1e-6)
    assert r["torque ripple"].measured == pytest.approx(200.0, rel=1e-6)


def test_statistic_check():
    t = _t(0.01)
    sig = SignalSet([Signal("ctrl.torque_ref_nm", t, np.full(len(t), 2.0), "Nm")])
    _, spec = _check("""
name: saturated
kind: statistic
statistic: mean
signal: ctrl.torque_ref_nm
limits: {low: 1.9, high: 2.05, unit: Nm}
""")
    r = evaluate_check(spec, sig, {})
    assert r.outcome is Outcome.PASS and r.measured == pytest.approx(2.0)


# --------------------------------------------------------- errors, not crashes

def test_missing_signal_is_an_error_naming_file_line_and_signal():
    sig = SignalSet([Signal("plant.speed_rpm", _t(0.1), np.zeros(2001), "rpm")])
    _, spec = _check("""
name: ekf speed
kind: rms_error
signal: ctrl.speed_ekf_rad_s
reference: plant.speed_rad_s
limits: {high: 20, unit: rpm}
""")
    r = evaluate_check(spec, sig, {})
    assert r.outcome is Outcome.ERROR
    assert r.measured is None
    assert r.message.startswith(f"synthetic.yaml:{spec.line}: check 'ekf speed': ")
    assert "signal 'ctrl.speed_ekf_rad_s' was not recorded" in r.message


def test_window_after_the_data_is_an_error():
    sig = _speed_step_signals()
    _, spec = _check("""
name: too late
kind: final_value
signal: plant.speed_rpm
window: {from: step, duration_s: 1.0}
limits: {high: 1, unit: rpm}
""", prefix="  - mark: step\n")
    r = evaluate_check(spec, sig, {"step": 0.1})
    assert r.outcome is Outcome.ERROR and "ends after the recording" in r.message


def test_unrecorded_mark_is_an_error():
    sig = _speed_step_signals()
    _, spec = _check("""
name: needs mark
kind: final_value
signal: plant.speed_rpm
window: {from: step}
limits: {high: 1, unit: rpm}
""", prefix="  - mark: step\n")
    r = evaluate_check(spec, sig, {})
    assert r.outcome is Outcome.ERROR and "mark 'step' was not recorded" in r.message


def test_compare_with_an_errored_check_is_an_error():
    plan = parse_plan("""
name: c
steps:
  - check: {name: a, kind: final_value, signal: plant.speed_rpm, limits: {high: 1, unit: rpm}}
  - check: {name: b, kind: compare, a: a, b: a, limits: {high: 1, unit: "1"}}
""", "c.yaml")
    a = evaluate_check(plan.checks[0], SignalSet(), {}, now_s=1.0)
    b = evaluate_check(plan.checks[1], SignalSet(), {}, results={"a": a}, now_s=1.0)
    assert a.outcome is Outcome.ERROR and b.outcome is Outcome.ERROR
    assert "no finite measured value" in b.message


def test_result_json_round_trip_keeps_infinity_and_drops_plot_arrays():
    sig = _speed_step_signals()
    _, spec = _check("""
name: never
kind: settling_time
signal: plant.speed_rpm
window: {from: start, duration_s: 0.05}
target: {value: 3000, unit: rpm}
initial: {value: 1500, unit: rpm}
limits: {high: 150, unit: ms}
""")
    r = evaluate_check(spec, sig, {})
    assert r.outcome is Outcome.FAIL and r.measured == math.inf
    data = r.to_json()
    assert data["measured"] == "inf"
    assert CheckResult.from_json(data).measured == math.inf


def test_ramp_lag_of_a_low_pass_filter_is_its_time_constant_and_of_a_delay_its_delay():
    tau = 1 / (2 * np.pi * 20.0)                    # the stub's 20 Hz filter: 7.96 ms
    t = _t(0.1)
    truth = 1500.0 + 2500.0 * t * 30 / np.pi        # a torque-limited ramp in rpm
    a = 1.0 - np.exp(-DT / tau)
    filt = np.empty_like(truth)
    acc = truth[0]
    for i, x in enumerate(truth):
        acc += a * (x - acc)
        filt[i] = acc
    late = t >= 6 * tau                             # after the filter's transient
    lag, d = checks.ramp_lag_s(t[late], filt[late], truth[late])
    assert lag == pytest.approx(tau - DT / 2, rel=5e-3)   # the discrete filter's half-sample
    assert d["r2"] == pytest.approx(1.0)
    delayed = np.interp(t - 0.0016, t, truth)
    assert checks.ramp_lag_s(t[late], delayed[late], truth[late])[0] == pytest.approx(0.0016, rel=1e-6)


def test_ramp_lag_refuses_a_window_without_a_ramp():
    t = _t(0.05)
    step = np.where(t < 0.025, 0.0, 1.0)
    with pytest.raises(CheckError, match="not a ramp"):
        checks.ramp_lag_s(t, step, step)
    with pytest.raises(CheckError, match="constant"):
        checks.ramp_lag_s(t, np.ones(len(t)), np.ones(len(t)))


def test_a_board_signal_that_is_nan_throughout_fails_the_check_naming_it():
    """SPEC 6.5: a board fills what it does not compute with NaN. A check on such a signal is a
    verdict on the board (FAIL, naming the signal), not an error of the plan or the bench."""
    t = _t(0.2)
    sig = SignalSet([Signal("plant.speed_rpm", t, np.full(len(t), 1500.0), "rpm"),
                     Signal("ctrl.speed_ekf_rad_s", t, np.full(len(t), np.nan), "rad/s")])
    _, spec = _check("""
name: EKF speed
kind: final_value
signal: ctrl.speed_ekf_rad_s
average_s: 0.01
limits: {low: 1490, high: 1510, unit: rpm}
""")
    r = evaluate_check(spec, sig, {})
    assert r.outcome is Outcome.FAIL and r.measured is None
    assert "reports no value for ctrl.speed_ekf_rad_s" in r.message
    # a plant signal that turns NaN is still an error: the bench, not the board, is wrong
    sig = SignalSet([Signal("plant.speed_rpm", t, np.full(len(t), np.nan), "rpm")])
    _, spec = _check("""
name: speed
kind: final_value
signal: plant.speed_rpm
average_s: 0.01
limits: {low: 1490, high: 1510, unit: rpm}
""")
    assert evaluate_check(spec, sig, {}).outcome is Outcome.ERROR
