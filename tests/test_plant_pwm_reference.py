"""PWM duties with dead time and device drop against an independent switched-circuit reference
(bench/_switched_reference.py: the circuit written from its equations, not from the plant's
code, integrated by scipy's solve_ivp with its switching and diode events located).

Limits (written before the first run, from issue 14): phase-current error at most 1e-6 of the
peak; DC-link energy to 1e-6 of the energy exchanged. Most runs are kept short (CI cost; the
rotor still turns through many current zero crossings at rated and twice rated speed); one
covers the issue's whole second at twice rated speed.
"""
from __future__ import annotations

import math

import pytest

from bench._switched_reference import (F, RATED_RAD_S, SwitchedCircuit, reference_period, run,
                                      start_after_first_period)
from plant_rt import Plant, load_profile


@pytest.mark.parametrize("speed", [RATED_RAD_S, 2.0 * RATED_RAD_S])
def test_pwm_dead_time_matches_switched_circuit_reference(speed):
    """Duties with 2 us dead time through current zero crossings (diode currents reaching
    zero, phases floating), rated and twice rated speed: phase currents to 1e-6 of the peak,
    DC-link energy to 1e-6 of the energy exchanged (issue 14's limits)."""
    result = run(speed, 1200, seed=1, td=2e-6, drop=0.0)
    assert result["crossings"] >= 6 and result["peak"] > 3.0
    assert result["current_rel"] < 1e-6
    assert result["energy_rel"] < 1e-6


def test_one_second_of_pwm_with_dead_time_and_drop_at_twice_rated_speed_matches_the_reference():
    """Issue 14's span: 1 s (20,000 periods, about a minute here) of random duties with 2 us
    dead time and a 1.5 V drop at twice rated speed, where the line back-EMF (101 V peak)
    exceeds the 70 V link and a phase whose current reaches zero in a dead time often has its
    high diode take over at once: phase currents to 1e-6 of the peak, energy to 1e-6."""
    result = run(2.0 * RATED_RAD_S, 20000, seed=5, td=2e-6, drop=1.5)
    # that the run goes through hundreds of zero crossings (100 electrical turns, two per
    # phase each at most): a guard on what the test exercises, not a limit on the plant
    assert result["crossings"] >= 300 and result["peak"] > 3.0
    assert result["current_rel"] < 1e-6
    assert result["energy_rel"] < 1e-6


@pytest.mark.parametrize("speed, seed", [(RATED_RAD_S, 2), (2.0 * RATED_RAD_S, 3)])
def test_pwm_dead_time_and_device_drop_match_switched_circuit_reference(speed, seed):
    """2 us dead time and a 1.5 V device drop with its 0.1 A knee, where a driven leg's current
    crosses the knee (the drop's kink, located as an event since 2026-11-24; 1e-4 of the peak
    before) and diode currents reach zero: phase currents and energy to 1e-6."""
    result = run(speed, 1200, seed=seed, td=2e-6, drop=1.5)
    assert result["crossings"] >= 6
    assert result["current_rel"] < 1e-6
    assert result["energy_rel"] < 1e-6


def test_reference_sees_dead_time():
    """The reference is not blind: without dead time in the plant (but with it in the
    reference) the currents differ far beyond the limit."""
    T = 50e-6
    profile = load_profile(overrides={"initial": {"speed_rad_s": RATED_RAD_S}})
    circ = SwitchedCircuit(profile.motor, 70.0, 0.0, 0.1)
    plant = Plant(profile)
    s, modes = start_after_first_period(plant, (0.5, 0.5, 0.5))
    err = 0.0
    for k in range(100):
        th = s[3] + 1.8
        duty = tuple(0.5 + 0.35 * math.cos(th - 2 * math.pi * x / 3) for x in range(3))
        s = reference_period(circ, s, duty, T, 2e-6, modes)
        plant.step(duty=duty)
        err = max(err, abs(plant.truth()[F["i_a"]] - s[0]))
    assert err > 1e-3
