"""The plant kernel's float-to-integer conversions are range-checked (plant_rt/c/_plantnet.c).

An interval whose RK4 step count, ceil(length / h_max), is NaN, infinite or above 2^31 - 1, and
a configuration integer (DC-link mode, open phase, index-pulse bit) that is NaN or out of range,
raise ValueError into Python. Before, C converted them out of range (undefined behaviour:
`make -C plant_rt/c ext-san` stops on it with float-cast-overflow) and went on with a garbage
step count, or would loop for ever. Finite in-range inputs keep their results bit for bit:
tests/test_plant_c_network.py and tests/test_plant_duty_fast.py compare them with the Python
reference.
"""
from __future__ import annotations

import math

import pytest

from plant_rt import Plant, ckernel, load_profile

pytestmark = pytest.mark.skipif(ckernel.EXTENSION is None,
                                reason=f"C kernel not built: {ckernel.UNAVAILABLE_REASON}")

# 1 us / 1e-300 s: 1e294 steps, far beyond a long; 1 us / (50 us / 3e12): 6e10 steps, within a
# long but beyond 2^31 - 1 (the shortest interval these tests integrate is about 1 us)
TINY_H_MAX_S = [1e-300, 50e-6 / 3e12]
STEP_COUNT = "RK4 step count"


def _plant(**overrides) -> Plant:
    plant = Plant(load_profile(overrides=overrides), seed=0)
    plant.use_c_kernel(True)
    return plant


@pytest.mark.parametrize("h_max", TINY_H_MAX_S)
def test_integrate_refuses_a_step_count_beyond_a_long(h_max):
    ext = ckernel.EXTENSION
    plant = _plant()
    k, cfg = plant.motor._k, plant.network._cfg()
    y = [0.09, 0.0, 10.0, 0.0, 70.0]
    # the same call with a sane h_max runs (the arguments are otherwise valid)
    ext.integrate(k, cfg, [0, 1, 1], 0.0, 50e-6, list(y), 5e-6, [0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match=STEP_COUNT):
        ext.integrate(k, cfg, [0, 1, 1], 0.0, 50e-6, list(y), h_max, [0.0, 0.0, 0.0])


@pytest.mark.parametrize("index, value", [(0, math.nan), (0, math.inf), (0, -1e300),
                                          (12, math.nan), (12, -math.inf), (12, 1e300)])
def test_integrate_refuses_configuration_integers_out_of_range(index, value):
    ext = ckernel.EXTENSION
    plant = _plant()
    k, cfg = plant.motor._k, list(plant.network._cfg())
    cfg[index] = value
    with pytest.raises(ValueError, match="dc_mode or open_phase"):
        ext.integrate(k, tuple(cfg), [0, 1, 1], 0.0, 50e-6, [0.09, 0.0, 10.0, 0.0, 70.0], 5e-6,
                      [0.0, 0.0, 0.0])


@pytest.mark.parametrize("h_max", TINY_H_MAX_S)
def test_leg_period_refuses_a_step_count_beyond_a_long(h_max):
    ext = ckernel.EXTENSION
    plant = _plant(inverter={"dead_time_s": 1e-6})
    m, T = plant.motor, plant._T
    windows = plant._timeline._duty_windows((0.3, 0.5, 0.7))
    # 5 A in alpha, 3 A in beta, turning: every current clear of zero, so the period is one
    # the constant-vector form takes (at zero current it would answer False before integrating)
    state = (m.psim + m.ld * 5.0, m.ld * 3.0, 10.0, 0.0)
    args = (m._k, m.ld, m.spm, T, windows, 0.0, 0.1, 70.0, state)
    assert isinstance(ext.leg_period(*args, 5e-6, 0.0, 0.0, 0.0), tuple)   # sane: it runs
    with pytest.raises(ValueError, match=STEP_COUNT):
        ext.leg_period(*args, h_max, 0.0, 0.0, 0.0)


@pytest.mark.parametrize("h_max", TINY_H_MAX_S)
@pytest.mark.parametrize("command", ["duty", "gates"])
def test_the_plant_step_raises_rather_than_converting_out_of_range(h_max, command):
    """Through Plant.step: the DUTY fast path (duty_period) and the gate path's kernel calls."""
    plant = _plant(inverter={"dead_time_s": 1e-6})
    for _ in range(3):      # the first periods fill the load-segment cache the fast path reads
        plant.step(duty=(0.3, 0.5, 0.7))
    plant._h_max = h_max
    plant._bind_duty_period()
    with pytest.raises(ValueError, match=STEP_COUNT):
        if command == "duty":
            plant.step(duty=(0.3, 0.5, 0.7))
        else:
            plant.step(gates=0x19)


@pytest.mark.parametrize("pulse_bit", [math.nan, -1.0, 1e300])
def test_duty_period_refuses_an_index_pulse_bit_out_of_range(pulse_bit):
    plant = _plant(inverter={"dead_time_s": 1e-6})
    assert plant._duty_period is not None
    for _ in range(3):      # the first periods fill the load-segment cache the fast path reads
        plant.step(duty=(0.3, 0.5, 0.7))
    plant._duty_cfg = plant._duty_cfg[:-1] + (pulse_bit,)
    with pytest.raises(ValueError, match="pulse bit"):
        plant.step(duty=(0.3, 0.5, 0.7))
