"""Plant fault hooks against analytic results: open phase, stuck gates, DC ripple and ramps,
parameter drift, sensor and encoder faults (plant_rt; hil/faults/injector.py switches them)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from plant_rt import TRUTH_FIELDS, Plant, load_profile
from plant_rt.plant import PARAM_RAMP_UPDATE_S
from plant_rt.sensors import STATUS_GATE_FAULT, STATUS_INDEX_PULSE

F = {name: i for i, name in enumerate(TRUTH_FIELDS)}
V1, V2, V6 = 0x29, 0x25, 0x19
R, LS, PSI_M, J, B = 0.466, 4.8e-3, 0.0928, 8.0e-4, 1.0e-4
T = 50e-6
LSB_I = 25.0 / 2048


def _merge(base: dict, extra: dict) -> dict:
    out = dict(base)
    for key, value in extra.items():
        out[key] = _merge(out.get(key, {}), value) if isinstance(value, dict) else value
    return out


def quiet(**sections):
    """The paper's profile without ADC noise, plus overrides."""
    return load_profile(overrides=_merge({"sensors": {"current": {"noise_rms_counts": 0.0},
                                                      "dc_voltage": {"noise_rms_counts": 0.0}}},
                                         sections))


def locked(vdc: float = 7.0) -> Plant:
    return Plant(quiet(load={"locked": True}, dc_link={"source_voltage_v": vdc}))


def run(plant: Plant, gates, periods: int) -> np.ndarray:
    rows = []
    for _ in range(periods):
        plant.step(gates)
        rows.append(plant.truth())
    return np.asarray(rows)


# --------------------------------------------------------------------------- open phase
@pytest.mark.parametrize("phase, gates, driven, cut", [
    ("a", V2, "i_b", "i_a"),    # B high, C low: the current goes b -> c
    ("b", V1, "i_a", "i_b"),    # A high, C low: a -> c
    ("c", V1, "i_a", "i_c"),    # A high, B low: a -> b
])
def test_open_phase_leaves_a_series_rl_circuit(phase, gates, driven, cut):
    """Locked rotor (no back-EMF), one phase disconnected: the other two carry one current
    through 2R and 2Ls (the synchronous inductance, since the currents sum to zero), so
    i(t) = Vdc / (2R) (1 - exp(-t R / Ls)); the cut phase carries exactly nothing."""
    plant = locked()
    plant.set_open_phase(phase)
    rows = run(plant, gates, 200)
    t = rows[:, F["t_s"]]
    expected = 7.0 / (2 * R) * (1 - np.exp(-t * R / LS))
    np.testing.assert_allclose(rows[:, F[driven]], expected, rtol=1e-7, atol=1e-9)
    assert np.all(rows[:, F[cut]] == 0.0)
    others = [n for n in ("i_a", "i_b", "i_c") if n != cut]
    assert np.all(rows[:, F[others[0]]] == -rows[:, F[others[1]]])
    # What the board reads agrees: the cut phase's ADC sits at its zero code.
    if cut in ("i_a", "i_b"):
        code = plant.sample().adc_i1 if cut == "i_a" else plant.sample().adc_i2
        assert code == 2048


def test_open_phase_cuts_a_flowing_current_and_reconnecting_restores_the_circuit():
    plant = locked()
    run(plant, V1, 100)
    assert plant.truth()[F["i_a"]] > 1.0
    plant.set_open_phase("a")
    assert plant.sample().adc_i1 == 2048       # the next sample already reads zero
    rows = run(plant, V1, 50)
    assert np.all(rows[:, F["i_a"]] == 0.0)
    plant.set_open_phase(None)
    i_before = plant.truth()[F["i_a"]]
    rows = run(plant, V1, 50)
    assert rows[-1, F["i_a"]] > i_before + 0.5     # V1 drives phase a again


def test_open_phase_at_speed_keeps_the_other_two_opposite():
    """A drive at 150 rad/s switching Table 2 vectors with phase b cut: the network path with
    back-EMF, floating terminal and diode events; i_b is exactly zero, i_a = -i_c, and the
    torque is that of a single-phase current (it pulsates: it goes through zero)."""
    plant = Plant(quiet(initial={"speed_rad_s": 150.0}))
    plant.set_open_phase("b")
    words = [0x29, 0x25, 0x26, 0x16, 0x1A, 0x19]
    rows = []
    for k in range(1200):
        plant.step(words[(k // 20) % 6])
        rows.append(plant.truth())
    rows = np.asarray(rows)
    assert np.all(rows[:, F["i_b"]] == 0.0)
    assert np.all(rows[:, F["i_a"]] == -rows[:, F["i_c"]])
    assert np.max(np.abs(rows[:, F["i_a"]])) > 1.0
    torque = rows[:, F["torque_nm"]]
    assert torque.min() < 0.05 * torque.max() or torque.max() < 0.05 * abs(torque.min())


# --------------------------------------------------------------------------- stuck gates
def test_gate_stuck_on_completes_an_open_leg():
    """Commanded A high, B low, C open (0x09) with C's high switch stuck on: the inverter
    applies V6 (101): u = (Vdc / 3, -Vdc / sqrt3) (Table 2), the same motion as V6 itself."""
    faulty, reference = locked(), locked()
    faulty.set_gate_stuck("c_high", "on")
    a = run(faulty, 0x09, 100)
    b = run(reference, V6, 100)
    np.testing.assert_allclose(a[:, F["u_alpha"]], 7.0 / 3, rtol=1e-12)
    np.testing.assert_allclose(a[:, F["u_beta"]], -7.0 / math.sqrt(3), rtol=1e-12)
    np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-12)
    assert faulty.gates_stuck == {"c_high": "on"}


def test_gate_stuck_off_opens_its_leg():
    """V1 with A's high switch stuck off: leg A is open; from rest with B and C low nothing can
    drive a current (without the fault i_a rises towards 2/3 Vdc / R)."""
    faulty, healthy = locked(), locked()
    faulty.set_gate_stuck("a_high", "off")
    a = run(faulty, V1, 100)
    b = run(healthy, V1, 100)
    assert np.max(np.abs(a[:, [F["i_a"], F["i_b"], F["i_c"]]])) < 1e-12
    assert np.max(np.abs(a[:, [F["u_alpha"], F["u_beta"]]])) < 1e-9
    assert b[-1, F["i_a"]] > 2.0
    faulty.set_gate_stuck("a_high", None)
    assert faulty.gates_stuck == {}
    c = run(faulty, V1, 100)
    np.testing.assert_allclose(c[:, F["i_a"]], b[:, F["i_a"]], rtol=1e-9)


def test_gate_stuck_on_against_its_partner_is_a_shoot_through():
    """A's low switch stuck on while the board commands A high: both switches of leg A on.
    The gate driver's desaturation trips (GATE_FAULT in the next sample) and opens the leg."""
    faulty = locked()
    faulty.set_gate_stuck("a_low", "on")
    faulty.step(V1)
    assert faulty.sample().status & STATUS_GATE_FAULT
    rows = run(faulty, V1, 50)
    assert np.max(np.abs(rows[:, F["i_a"]])) < 1e-12


# --------------------------------------------------------------------------- DC link
def test_dc_ripple_is_a_sine_held_at_each_period_midpoint():
    plant = Plant(quiet())
    plant.set_dc_ripple(7.0, 300.0)
    v = run(plant, V1, 200)[:, F["v_dc"]]
    k = np.arange(200)
    np.testing.assert_allclose(v, 70.0 + 7.0 * np.sin(2 * np.pi * 300.0 * (k + 0.5) * T),
                               rtol=0, atol=1e-12)
    plant.set_dc_ripple(0.0, 0.0)
    assert run(plant, V1, 3)[-1, F["v_dc"]] == 70.0
    with pytest.raises(ValueError, match="Nyquist"):
        plant.set_dc_ripple(1.0, 15000.0)


def test_dc_ramp_is_linear_and_lands_exactly():
    plant = Plant(quiet())
    plant.ramp_dc_voltage(49.0, 0.005)                    # 100 periods
    v = run(plant, V1, 150)[:, F["v_dc"]]
    k = np.arange(100)
    np.testing.assert_allclose(v[:100], 70.0 - 21.0 * (k + 0.5) / 100, atol=1e-9)
    assert np.all(v[100:] == 49.0)
    assert plant.dc_source_voltage_v == 49.0
    assert "step" not in vars(plant)                       # the hook is gone with the ramp


def test_dc_surge_raises_the_overvoltage_bit():
    plant = Plant(quiet())
    plant.set_dc_voltage(1.3 * 70.0)
    plant.step(V1)
    assert plant.sample().status & 0x04


# --------------------------------------------------------------------------- parameter drift
def test_resistance_drift_changes_the_rl_response():
    """Locked rotor, V1 from rest: i_a = (2/3 Vdc / R)(1 - exp(-t R / Ls)) with the new R."""
    for factor in (1.0, 1.5):
        plant = locked()
        plant.ramp_motor_param("resistance_ohm", R * factor, 0.0)
        rows = run(plant, V1, 400)
        t = rows[:, F["t_s"]]
        r = R * factor
        np.testing.assert_allclose(rows[:, F["i_a"]], 2 / 3 * 7.0 / r * (1 - np.exp(-t * r / LS)),
                                   rtol=1e-7, atol=1e-9)


def test_parameter_ramp_follows_a_staircase_and_ends_exactly():
    plant = Plant(quiet())
    plant.ramp_motor_param("resistance_ohm", 1.5 * R, 0.01)      # 200 periods
    every = round(PARAM_RAMP_UPDATE_S / T)
    seen = []
    for k in range(260):
        plant.step(V1)
        seen.append(plant.motor.r)
    seen = np.asarray(seen)
    ideal = R + 0.5 * R * np.minimum((np.arange(260) + 0.5) * T / 0.01, 1.0)
    assert np.all(np.abs(seen - ideal) <= 0.5 * R * every * T / 0.01 + 1e-12)
    assert len(np.unique(seen[:199])) <= 200 // every + 1
    assert seen[-1] == 1.5 * R
    assert "step" not in vars(plant)


def test_flux_linkage_drift_scales_the_back_emf():
    """All switches off at 100 rad/s (line back-EMF 16 V < 70 V: no current): the terminal
    voltage is the back-EMF p w psi_m, so a magnet at 90 % gives 90 % of it."""
    plant = Plant(quiet(initial={"speed_rad_s": 100.0}))
    plant.safe_state()
    rows = run(plant, None, 20)
    u = np.hypot(rows[:, F["u_alpha"]], rows[:, F["u_beta"]])
    np.testing.assert_allclose(u, rows[:, F["speed_rad_s"]] * PSI_M, rtol=1e-5)
    plant.ramp_motor_param("flux_linkage_wb", 0.9 * PSI_M, 0.0)
    rows = run(plant, None, 20)
    u = np.hypot(rows[:, F["u_alpha"]], rows[:, F["u_beta"]])
    np.testing.assert_allclose(u, rows[:, F["speed_rad_s"]] * 0.9 * PSI_M, rtol=1e-5)


@pytest.mark.parametrize("factor", [1.0, 2.0])
def test_inertia_drift_changes_the_coast_down(factor):
    """Coasting against 0.2 Nm with no current: J dw/dt = -B w - T_L, so
    w(t) = (w0 + T_L / B) exp(-B t / J) - T_L / B, with the drifted J."""
    plant = Plant(quiet(initial={"speed_rad_s": 100.0}, load={"torque_nm": 0.2}))
    plant.safe_state()
    plant.ramp_motor_param("inertia_kgm2", J * factor, 0.0)
    rows = run(plant, None, 400)
    t = rows[:, F["t_s"]]
    j, tl = J * factor, 0.2
    np.testing.assert_allclose(rows[:, F["speed_rad_s"]],
                               (100.0 + tl / B) * np.exp(-B * t / j) - tl / B, rtol=1e-9)


def test_inductance_alias_drifts_both_axes():
    plant = Plant(quiet())
    plant.set_motor_param("inductance_h", 5.0e-3)
    assert plant.motor.ld == plant.motor.lq == 5.0e-3
    with pytest.raises(ValueError, match="unknown motor parameter 'bogus'"):
        plant.set_motor_param("bogus", 1.0)


# --------------------------------------------------------------------------- sensors
def test_adc_offset_gain_stuck_and_saturation():
    plant = locked()
    run(plant, V1, 200)
    i_a = plant.truth()[F["i_a"]]
    ch = plant.sensors.i1
    ch.offset_counts = 2048 + 82
    ch.gain = 1.1
    plant.step(V1)
    i_a = plant.truth()[F["i_a"]]
    assert plant.sample().adc_i1 == math.floor(2048 + 82 + 1.1 * i_a / LSB_I + 0.5)
    ch.saturation = (2000, 2100)
    plant.step(V1)
    assert plant.sample().adc_i1 == 2100
    ch.saturation = None
    ch.stuck_counts = 1234
    plant.step(V1)
    assert plant.sample().adc_i1 == 1234
    ch.stuck_counts = None
    plant.step(V1)
    assert plant.sample().adc_i1 > 2100
    with pytest.raises(ValueError, match="saturation window"):
        ch.saturation = (3000, 5000)


def test_extra_adc_noise_adds_in_quadrature_and_lifts():
    plant = Plant(load_profile(), seed=4)                   # 0.5 count rms of its own
    plant.sensors.i1.set_extra_noise(10.0, seed=9)
    codes = []
    for _ in range(20000):
        codes.append(plant.sample().adc_i1)
        plant.step()
    assert np.std(codes) == pytest.approx(math.hypot(0.5, 10.0), rel=0.03)
    plant.sensors.i1.clear_extra_noise()
    assert plant.sensors.i1.noise_rms_counts == 0.5
    codes = []
    for _ in range(5000):
        codes.append(plant.sample().adc_i1)
        plant.step()
    assert np.std(codes) < 0.8


def _spinning(speed: float = 300.0) -> Plant:
    # Coasting with all switches off and no damping: a constant speed, a known angle.
    return Plant(quiet(initial={"speed_rad_s": speed}, motor={"damping_nm_per_rad_s": 0.0}))


def _true_count(plant: Plant) -> int:
    enc = plant.sensors.encoder
    st = plant.state
    return enc.position(st["revolutions"], st["theta_m_rad"])


def test_encoder_lost_freezes_the_counter():
    plant = _spinning()
    plant.safe_state()
    plant.step()
    frozen = plant.encoder_count()
    plant.sensors.encoder.stuck_counts = frozen
    counts = set()
    for _ in range(100):
        plant.step()
        counts.add(plant.sample().encoder)
    assert counts == {frozen}


def test_encoder_missing_counts_lose_the_stated_fraction():
    """At 300 rad/s a 4096-count encoder makes 9.8 edges per period; each is lost with
    probability 0.1, and the counter's deficit is exactly the edges lost (they accumulate)."""
    plant = _spinning()
    plant.safe_state()
    enc = plant.sensors.encoder
    plant.sample()
    start = _true_count(plant)
    enc.set_missing_counts(0.1, seed=5)
    for _ in range(2000):
        plant.step()
        s = plant.sample()
        assert s.encoder == (_true_count(plant) - enc.lost_counts) & 0xFFFF
    edges = _true_count(plant) - start
    sigma = math.sqrt(edges * 0.1 * 0.9)
    assert abs(enc.lost_counts - 0.1 * edges) < 4 * sigma
    enc.set_missing_counts(0.0)
    lost = enc.lost_counts
    plant.step()
    assert plant.sample().encoder == (_true_count(plant) - lost) & 0xFFFF   # what was lost stays lost


def test_encoder_noise_jitters_without_accumulating():
    plant = _spinning()
    plant.safe_state()
    plant.sensors.encoder.set_noise(3.0, seed=2)
    err = []
    for _ in range(5000):
        plant.step()
        e = (plant.sample().encoder - _true_count(plant)) & 0xFFFF
        err.append(e - 0x10000 if e > 0x8000 else e)
    err = np.asarray(err)
    assert abs(err.mean()) < 0.2
    assert err.std() == pytest.approx(3.0, rel=0.05)
    plant.sensors.encoder.set_noise(0.0)
    plant.step()
    assert plant.sample().encoder == _true_count(plant) & 0xFFFF


def test_index_pulse_missing():
    def passes(plant: Plant) -> int:
        n = 0
        for _ in range(1000):                          # 0.05 s at 300 rad/s: 2.4 turns
            plant.step()
            n += bool(plant.sample().status & STATUS_INDEX_PULSE)
        return n

    healthy, faulty = _spinning(), _spinning()
    healthy.safe_state()
    faulty.safe_state()
    faulty.sensors.encoder.index_missing = True
    assert passes(healthy) >= 2 and passes(faulty) == 0
    faulty.sensors.encoder.index_missing = False
    assert passes(faulty) >= 2


def test_no_fault_no_hook():
    """The fault hooks cost nothing while off: step() is the class's own method."""
    plant = Plant(quiet())
    assert "step" not in vars(plant)
    plant.set_dc_ripple(1.0, 50.0)
    assert "step" in vars(plant)
    plant.set_dc_ripple(0.0, 0.0)
    assert "step" not in vars(plant)
    assert plant.sensors.i1._plain and plant.sensors.encoder._plain
