"""The plant's C kernel (plant_rt/c/_plantnet.c) against its Python reference, period by period.

Two plants from the same profile and seed take the same commands, one with the slow paths in C
(Network.integrate and begin's settling, Plant._leg_period), one in Python (plant_rt/circuit.py,
plant_rt/plant.py, the reference). After every period their truth records must agree to 1e-12
of each signal's range over the run (the C code mirrors the Python operation by operation, so
in practice they are bit-identical; the limit leaves room for a libm or compiler difference).
Scenarios: random PWM duties with dead time and device drop through current zero crossings and
knee crossings, at rated and twice rated speed; the safe state coasting at twice rated speed
(diodes conducting into the link, then no current); gate words with a computation delay; an open
phase; a dynamic and a resistive DC link; a locked rotor; a load table with a step. The
comparison, the counting wrapper of the extension and the scenarios are
bench/_plant_accuracy_ckernel.py's (`python -m bench plant_accuracy` prints the values).

One test perturbs a motor constant in the arguments of the C calls only (1e-9 relative): the
same comparison must then fail, so it is shown that it can. The solve_ivp reference tests
(tests/test_plant_pwm_reference.py, tests/test_plant_accuracy.py) run whichever path is the
default, which is C when the kernel is built.
"""
from __future__ import annotations

import os
import random
import subprocess
import sys
from pathlib import Path

import pytest

from bench._plant_accuracy_ckernel import PERTURBED, SCENARIOS, Counting
from bench._plant_accuracy_ckernel import compare as compare_paths
from plant_rt import Plant, ckernel, load_profile

ROOT = Path(__file__).resolve().parents[1]
LIMIT = 1e-12

needs_kernel = pytest.mark.skipif(ckernel.EXTENSION is None,
                                  reason=f"C kernel not built: {ckernel.UNAVAILABLE_REASON}")


def compare(overrides: dict, n: int, seed: int, mode: str = "duty", setup=None,
            kernel=None) -> tuple[float, Counting, Plant]:
    """bench/_plant_accuracy_ckernel.py's compare (worst |C - Python| over the run, per signal
    relative to its range), the two plants having met the same network events."""
    worst, kernel, c_plant, py_plant = compare_paths(overrides, n, seed, mode, setup, kernel)
    assert c_plant.network.events == py_plant.network.events
    return worst, kernel, py_plant


@needs_kernel
def test_default_is_the_c_kernel_unless_pure_python_is_asked():
    plant = Plant(load_profile(), seed=0)
    assert plant.c_kernel == (not ckernel.PURE_PYTHON)
    env = {**os.environ, "HIL_PLANT_PURE_PYTHON": "1"}
    out = subprocess.run(
        [sys.executable, "-c", "from plant_rt import Plant, load_profile, ckernel; "
         "print(Plant(load_profile()).c_kernel, ckernel.AVAILABLE)"],
        cwd=ROOT, env=env, capture_output=True, text=True, check=True).stdout.split()
    assert out == ["False", "True"]


def test_without_the_extension_the_plant_runs_python_and_says_why():
    env = {**os.environ, "HIL_PLANT_C_PATH": str(ROOT / "plant_rt" / "c" / "build" / "absent.so")}
    env.pop("HIL_PLANT_PURE_PYTHON", None)
    code = ("from plant_rt import Plant, load_profile, ckernel\n"
            "p = Plant(load_profile(overrides={'inverter': {'dead_time_s': 2e-6}}))\n"
            "p.step(duty=(0.2, 0.5, 0.8))\n"
            "try:\n    p.use_c_kernel(True)\nexcept ImportError as e:\n    print('refused:', e)\n"
            "print(ckernel.AVAILABLE, p.c_kernel, ckernel.UNAVAILABLE_REASON)")
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, env=env, capture_output=True,
                         text=True, check=True).stdout
    assert out.startswith("refused: ") and "not built" in out
    assert "\nFalse False " in out


@needs_kernel
@pytest.mark.parametrize("scenario", ["pwm_dead_time_drop_rated", "pwm_dead_time_drop_twice_rated"])
def test_pwm_with_dead_time_and_drop_c_equals_python(scenario):
    worst, kernel, ref = compare(*SCENARIOS[scenario])
    assert worst <= LIMIT
    assert kernel.calls["leg_period"] > 0 and kernel.calls["period"] > 0
    assert kernel.calls["duty_windows"] > 0
    assert ref.network.events > 20          # diode zero crossings and knee crossings were met


@needs_kernel
def test_pwm_with_dead_time_through_zero_crossings_from_standstill():
    worst, kernel, ref = compare(*SCENARIOS["pwm_dead_time_from_standstill"])
    assert worst <= LIMIT
    # the network, the driven and the diode intervals of the general path (in one call a
    # period, fast_period, on an ideal link)
    assert kernel.calls["integrate"] + kernel.calls["period"] + kernel.calls["fast_period"] > 0
    assert ref.network.events > 0
    assert kernel.calls["advance"] + kernel.calls["fast_period"] > 0


@needs_kernel
def test_pwm_with_dead_time_near_current_zeros_at_low_speed_c_equals_python():
    """Small balanced duties at 20 rad/s with 1 us dead time: most periods leave leg_period
    (a current crosses zero) for the per-interval path, in C fast_period: the fast RK4, the
    diode-equivalent trial, the network where a diode current reaches zero."""
    worst, kernel, ref = compare(*SCENARIOS["pwm_dead_time_low_speed_small_current"])
    assert worst <= LIMIT
    assert kernel.calls["fast_period"] > 500 and ref.network.events > 100
    assert kernel.calls["word_intervals"] > 500


@needs_kernel
def test_the_word_interval_sweep_c_equals_python():
    """Random on-windows per switch (starting at or before 0, ending at or after T, touching,
    sharing edges with other switches): the kernel's sweep gives Timeline._word_intervals'
    intervals exactly; more toggles than it holds: None (the Python sweep runs)."""
    from plant_rt.inverter import SwitchTimeline

    T = 50e-6
    timeline = SwitchTimeline(T, 0.0, 0.0)
    rng = random.Random(7)
    grid = [i * T / 8 for i in range(9)]        # shared edges, 0 and T among them
    for _ in range(2000):
        windows = []
        for _ in range(6):
            edges = sorted(rng.sample(grid + [rng.uniform(-T, 2 * T) for _ in range(2)],
                                      2 * rng.randrange(0, 4)))
            windows.append([(edges[i], edges[i + 1]) for i in range(0, len(edges), 2)])
        assert ckernel.EXTENSION.word_intervals(T, windows) == timeline._word_intervals(windows)
    many = [[(i * 1e-7, i * 1e-7 + 5e-8) for i in range(1, 100)]] + [[] for _ in range(5)]
    assert ckernel.EXTENSION.word_intervals(T, many) is None


@needs_kernel
def test_safe_state_coast_at_twice_rated_speed_c_equals_python():
    worst, kernel, ref = compare(*SCENARIOS["safe_state_twice_rated"])
    assert worst <= LIMIT
    assert ref.network.events > 10 and kernel.calls["period"] > 0


@pytest.mark.parametrize("name", ["gate_words_full_period_delay", "open_phase", "dynamic_link",
                                  "resistive_link", "locked_rotor", "load_table_with_a_step",
                                  "interior_magnet"])
@needs_kernel
def test_other_network_paths_c_equal_python(name):
    worst, kernel, _ = compare(*SCENARIOS[name])
    assert worst <= LIMIT, name
    # (on an ideal link the general path's intervals go through fast_period)
    assert kernel.calls["integrate"] + kernel.calls["period"] + kernel.calls["fast_period"] > 0, name


@needs_kernel
def test_the_comparison_fails_when_the_c_side_gets_a_perturbed_resistance():
    worst, kernel, _ = compare(*PERTURBED, kernel=Counting(scale_r=1 + 1e-9))
    assert kernel.calls["leg_period"] > 0
    assert worst > 100 * LIMIT


@needs_kernel
def test_duty_windows_c_equal_python_and_carry_the_dead_time_across_periods():
    from plant_rt.inverter import SwitchTimeline
    rng = random.Random(6)
    c_tl, py_tl = SwitchTimeline(50e-6, 0.0, 2e-6), SwitchTimeline(50e-6, 0.0, 2e-6)
    c_tl.kernel = ckernel.EXTENSION
    for _ in range(500):
        duty = tuple(rng.choice((0.0, 1.0, rng.random())) for _ in range(3))
        assert c_tl._duty_windows(duty) == py_tl._duty_windows(duty)
        assert c_tl._rise == py_tl._rise


@needs_kernel
def test_the_kernel_refuses_malformed_arguments():
    ext = ckernel.EXTENSION
    plant = Plant(load_profile(), seed=0)
    net = plant.network
    k, cfg = plant.motor._k, net._cfg()
    y = [0.09, 0.0, 10.0, 0.0, 70.0]
    with pytest.raises(ValueError):
        ext.integrate(k[:7], cfg, [0, 1, 1], 0.0, 5e-5, y, 5e-5, [0.0, 0.0, 0.0])
    with pytest.raises(ValueError):
        ext.integrate(k, cfg, [0, 1, 7], 0.0, 5e-5, y, 5e-5, [0.0, 0.0, 0.0])
    with pytest.raises(ValueError):
        ext.integrate(k, cfg, [0, 1, 1], 0.0, 5e-5, y, 0.0, [0.0, 0.0, 0.0])
    with pytest.raises(TypeError):
        ext.integrate(k, cfg, [0, 1, 1], 0.0, 5e-5, y, 5e-5, (0.0, 0.0, 0.0))
    with pytest.raises(TypeError):
        ext.leg_period(k, 4.8e-3, True, 5e-5, [[]] * 5, 0.0, 0.1, 70.0, y[:4], 5e-5, 0.0,
                       0.0, 0.0)
