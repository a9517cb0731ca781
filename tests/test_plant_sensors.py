"""Sensors as the board reads them: encoder counter, ADC codes, noise, faults, determinism."""
from __future__ import annotations

import math
import random

import numpy as np
import pytest

from plant_rt import TRUTH_FIELDS, Plant, SensorSample, load_profile

F = {name: i for i, name in enumerate(TRUTH_FIELDS)}
V1 = 0x29
LSB_I = 25.0 / 2048
LSB_V = 100.0 / 4096


def merge(base: dict, extra: dict) -> dict:
    out = dict(base)
    for key, value in extra.items():
        out[key] = merge(out.get(key, {}), value) if isinstance(value, dict) else value
    return out


def quiet(**sections):
    """The default profile without ADC noise, plus overrides."""
    return load_profile(overrides=merge({"sensors": {"current": {"noise_rms_counts": 0.0},
                                                     "dc_voltage": {"noise_rms_counts": 0.0}}},
                                        sections))


def nearest(x: float) -> int:
    return math.floor(x + 0.5)


def test_encoder_counts_across_wrap_and_direction_reversal():
    """Coasting against a constant (active) load: forward 1.7 turns, stop, back 3.9 turns
    through zero. The 16-bit counter is floor(theta_m 4096 / 2 pi) mod 65536 at every sample,
    it wraps below zero, and the index bit marks each pass through theta_m = 0."""
    p = quiet(initial={"speed_rad_s": 200.0}, load={"torque_nm": 1.5})
    plant = Plant(p)
    turns = 0
    prev_th = plant.truth()[F["theta_m_rad"]]
    prev_total = prev_th
    wrapped = reversed_ = False
    index_seen = 0
    last_count = None
    for k in range(round(0.3 / p.control_period_s)):
        s = plant.sample()
        t = plant.truth()
        th = t[F["theta_m_rad"]]
        if th - prev_th < -math.pi:
            turns += 1
        elif th - prev_th > math.pi:
            turns -= 1
        total = 2 * math.pi * turns + th
        expected = (turns * 4096 + math.floor(th * 4096 / (2 * math.pi))) % 65536
        assert s.encoder == expected
        crossed = math.floor(total / (2 * math.pi)) != math.floor(prev_total / (2 * math.pi))
        if k > 0:
            assert bool(s.status & 0x01) == crossed, k
        index_seen += crossed
        if last_count is not None and abs(s.encoder - last_count) > 30000:
            wrapped = True
        reversed_ |= t[F["speed_rad_s"]] < -50.0
        last_count, prev_th, prev_total = s.encoder, th, total
        plant.step()
    assert wrapped and reversed_
    assert index_seen >= 5


def test_encoder_counts_up_for_positive_rotation_from_index():
    p = quiet(initial={"speed_rad_s": 10.0})
    plant = Plant(p)
    assert plant.sample().encoder == 0
    for _ in range(20):
        plant.step()
    theta = plant.truth()[F["theta_m_rad"]]
    assert theta > 0 and plant.sample().encoder == math.floor(theta * 4096 / (2 * math.pi)) > 0


def test_adc_quantisation_is_nearest_code():
    """7 V link, locked rotor: the current rises through 0..10 A and each code is the nearest
    to 2048 + i / (25/2048) (phase a in adc_i1, phase b in adc_i2), the link 7 / (100/4096)."""
    p = quiet(load={"locked": True}, dc_link={"source_voltage_v": 7.0})
    plant = Plant(p)
    codes = set()
    for _ in range(2000):
        plant.step(gates=V1)
        s, t = plant.sample(), plant.truth()
        assert s.adc_i1 == nearest(2048 + t[F["i_a"]] / LSB_I)
        assert s.adc_i2 == nearest(2048 + t[F["i_b"]] / LSB_I)
        assert s.adc_vdc == nearest(7.0 / LSB_V) == 287
        codes.add(s.adc_i1)
    # The current really walked through the range (0 .. 10.01 A = 820 codes above 2048).
    assert min(codes) < 2060 and max(codes) > 2860 and len(codes) > 400


def test_adc_saturates_at_the_converter_range():
    """70 V locked rotor: i_a -> 100 A, i_b -> -50 A, beyond +-25 A full scale: 4095 and 0,
    with the overcurrent comparator bit set; a 120 V link reads 4095 and trips overvoltage."""
    p = quiet(load={"locked": True})
    plant = Plant(p)
    for _ in range(3000):
        plant.step(gates=V1)
    s = plant.sample()
    assert (s.adc_i1, s.adc_i2) == (4095, 0)
    assert s.status & 0x02 and not s.status & 0x04
    plant.set_dc_voltage(120.0)
    plant.step()
    s = plant.sample()
    assert s.adc_vdc == 4095 and s.status & 0x04


def test_current_pair_is_configurable():
    p = quiet(load={"locked": True}, dc_link={"source_voltage_v": 7.0},
              sensors={"current": {"phases": "bc"}})
    plant = Plant(p)
    for _ in range(100):
        plant.step(gates=V1)
    s, t = plant.sample(), plant.truth()
    assert s.adc_i1 == nearest(2048 + t[F["i_b"]] / LSB_I)
    assert s.adc_i2 == nearest(2048 + t[F["i_c"]] / LSB_I)
    plant.sensors.phases = "ac"
    plant.step()
    s, t = plant.sample(), plant.truth()
    assert s.adc_i1 == nearest(2048 + t[F["i_a"]] / LSB_I)
    assert s.adc_i2 == nearest(2048 + t[F["i_c"]] / LSB_I)
    with pytest.raises(ValueError, match="phases"):
        plant.sensors.phases = "ca"


def rounded_gaussian_rms(sigma: float) -> float:
    """rms of round(sigma * n), n standard normal."""
    total = 0.0
    for k in range(1, 12):
        s = sigma * math.sqrt(2)
        p = 0.5 * (math.erf((k + 0.5) / s) - math.erf((k - 0.5) / s))
        total += 2 * k * k * p
    return math.sqrt(total)


def test_adc_noise_is_seeded_gaussian_of_the_configured_rms():
    p = load_profile()                     # default: 0.5 count rms on every ADC
    plant = Plant(p, seed=7)
    codes = []
    for _ in range(20000):
        codes.append(plant.sample().adc_i1)
        plant.step()                       # idle: no current, exactly 2048.0 before noise
    dev = np.array(codes, dtype=float) - 2048
    assert abs(dev.mean()) < 0.02
    assert dev.std() == pytest.approx(rounded_gaussian_rms(0.5), rel=0.05)
    assert set(np.unique(dev)) <= {-3, -2, -1, 0, 1, 2, 3}


def test_runtime_sensor_faults_touch_only_their_channel():
    p = quiet(load={"locked": True}, dc_link={"source_voltage_v": 7.0})
    plant = Plant(p)
    for _ in range(3000):
        plant.step(gates=V1)
    i_a = plant.truth()[F["i_a"]]
    base = plant.sample()
    plant.sensors.i1.gain = 1.1
    plant.sensors.i1.offset = 0.5                       # amperes of transducer bias
    plant.sensors.vdc.stuck_counts = 123
    plant.step()
    s = plant.sample()
    assert s.adc_i1 == nearest(2048 + (1.1 * i_a + 0.5) / LSB_I)
    assert s.adc_i2 == base.adc_i2 and s.adc_vdc == 123
    plant.sensors.encoder.stuck_counts = 77
    plant.step()
    assert plant.sample().encoder == 77


def test_noise_streams_are_independent_per_channel():
    """Turning one channel's noise off does not shift another channel's noise sequence."""
    a, b = Plant(load_profile(), seed=3), Plant(load_profile(), seed=3)
    b.sensors.i1.noise_rms_counts = 0.0
    for _ in range(500):
        sa, sb = a.sample(), b.sample()
        assert sa.adc_i2 == sb.adc_i2 and sa.adc_vdc == sb.adc_vdc
        assert sb.adc_i1 == 2048
        a.step()
        b.step()


def random_session(seed: int, plant_seed: int) -> list:
    p = load_profile(overrides={"inverter": {"dead_time_s": 0.4e-6},
                                "timing": {"computation_delay_s": 12e-6},
                                "initial": {"speed_rad_s": 150.0}})
    plant = Plant(p, seed=plant_seed)
    rng = random.Random(seed)
    out = []
    for k in range(1500):
        out.append((plant.sample(), plant.truth()))
        r = rng.random()
        if r < 0.4:
            plant.step(gates=rng.choice((0x29, 0x25, 0x26, 0x16, 0x1A, 0x19, 0x2A, 0x15, 0)))
        elif r < 0.8:
            plant.step(duty=(rng.random(), rng.random(), rng.random()))
        else:
            plant.step()
        if k == 700:
            plant.load.set_step(plant.t_s + 1.3e-5, 0.4)
        if k == 900:
            plant.safe_state()
    return out


def test_determinism_bit_identical():
    """Same profile, seed and inputs (gates, duties, dead time, delay, load step, safe state)
    give identical samples and truth; another seed changes only the sensor noise."""
    a = random_session(1, plant_seed=5)
    b = random_session(1, plant_seed=5)
    assert a == b
    c = random_session(1, plant_seed=6)
    assert [t for _, t in a] == [t for _, t in c]
    assert [s for s, _ in a] != [s for s, _ in c]
    assert all(isinstance(s, SensorSample) for s, _ in a[:3])


def test_sample_is_taken_once_per_period():
    plant = Plant(load_profile(), seed=1)
    s1 = plant.sample()
    assert plant.sample() is s1 and s1.period == 0
    plant.step()
    assert plant.sample().period == 1
