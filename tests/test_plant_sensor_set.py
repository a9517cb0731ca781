"""Sensor sets (plant_rt.sensor_set, Plant.sensor_frame): Halls, terminal voltages and BEMF
comparators, three-phase current shunts, resolver, thermal model, against closed forms."""
from __future__ import annotations

import math

import pytest

from configfile.source import ConfigError
from plant_rt import TRUTH_FIELDS, Plant, SensorFrame, load_profile
from plant_rt.circuit import Network
from plant_rt.inverter import H, L, O, leg_states
from plant_rt.sensor_params import HallParams
from plant_rt.sensor_set import HallSensors
from plant_rt.thermal import ThermalModel, ThermalParams

F = {name: i for i, name in enumerate(TRUTH_FIELDS)}
V1, V4 = 0x29, 0x16        # (a b c) = (1 0 0), (0 1 1)
LSB_I = 25.0 / 2048
THIRD = 2.0 * math.pi / 3.0


def merge(base: dict, extra: dict) -> dict:
    out = dict(base)
    for key, value in extra.items():
        out[key] = merge(out.get(key, {}), value) if isinstance(value, dict) else value
    return out


def quiet(**sections):
    """The default profile without noise on any channel, plus overrides."""
    silent = {"noise_rms_counts": 0.0}
    return load_profile(overrides=merge(
        {"sensors": {name: silent for name in ("current", "dc_voltage", "terminal", "resolver",
                                               "temperature")}}, sections))


def wrap_deg(x: float) -> float:
    return (x + 180.0) % 360.0 - 180.0


def emf(psi: float, pole_pairs: int, theta_m: float, speed: float) -> list[float]:
    """The closed-form phase back-EMFs: e_x = -omega_e psi sin(theta_e - n_x 120 deg)."""
    we = pole_pairs * speed
    return [-we * psi * math.sin(pole_pairs * theta_m - n * THIRD) for n in range(3)]


# ------------------------------------------------------------------------------- Halls
def hall_edges(hall: HallSensors, start_deg: float, stop_deg: float, step_deg: float):
    """(angle_deg, word after) of every change of the Hall word on a monotone sweep."""
    n = round(abs(stop_deg - start_deg) / step_deg)
    sign = 1.0 if stop_deg > start_deg else -1.0
    word = hall.read(math.radians(start_deg))
    out = []
    for i in range(1, n + 1):
        deg = start_deg + sign * i * step_deg
        new = hall.read(math.radians(deg))
        if new != word:
            out.append((deg, new))
            word = new
    return out


def test_hall_word_sequence_and_edges_at_30_plus_60n_deg():
    hall = HallSensors(HallParams())
    edges = hall_edges(hall, -29.0, 331.0, 0.01)
    assert [w for _, w in edges] == [3, 2, 6, 4, 5, 1]
    for (deg, _), expected in zip(edges, (30, 90, 150, 210, 270, 330)):
        assert expected <= deg < expected + 0.01 + 1e-9


@pytest.mark.parametrize("direction", [+1, -1])
def test_hall_edges_shift_by_placement_error_and_half_the_hysteresis(direction):
    """Sensor x's edges sit at n_x 120 +- 90 deg + placement_error_x, h/2 late in the
    direction of rotation (on when cos > sin(h/2), off when cos < -sin(h/2))."""
    errors, h = (4.0, -7.0, 2.5), 10.0
    hall = HallSensors(HallParams(placement_error_deg=errors, hysteresis_deg=h))
    start = -45.0 if direction > 0 else 405.0
    edges = hall_edges(hall, start, start + direction * 450.0, 0.01)
    expected = []
    for x in range(3):
        for flip in (-90.0, 90.0):
            centre = x * 120.0 + errors[x] + flip
            expected.append(wrap_deg(centre + direction * h / 2))
    seen = [wrap_deg(deg) for deg, _ in edges]
    for angle in expected:
        assert min(abs(wrap_deg(angle - s)) for s in seen) < 0.01 + 1e-9, (angle, seen)
    assert len(edges) >= 6


def test_plant_hall_word_follows_the_rotor_and_stuck_sensors():
    p = quiet(initial={"speed_rad_s": 150.0})
    plant = Plant(p)
    words = []
    for k in range(round(2 * math.pi / 150.0 / p.control_period_s) + 5):
        f = plant.sensor_frame()
        th_e = plant.truth()[F["theta_e_rad"]]
        expected = sum((math.cos(th_e - x * THIRD) > 0) << x for x in range(3))
        assert f.hall == expected, k
        if not words or words[-1] != f.hall:
            words.append(f.hall)
        plant.step()
    start = words.index(1)
    assert (words[start:] + words[:start])[:6] == [1, 3, 2, 6, 4, 5]
    plant.sensors.hall.stuck[1] = 1
    plant.sensors.hall.stuck[0] = 0
    plant.step()
    th_e = plant.truth()[F["theta_e_rad"]]
    c_on = math.cos(th_e - 2 * THIRD) > 0
    assert plant.sensor_frame().hall == 0b010 | (c_on << 2)


# ------------------------------------------------------------- terminal voltages
def test_terminal_filter_step_response_is_one_minus_exp():
    """At rest with every leg off the terminals read 0 V; V1 from t_0 steps phase a to v_dc:
    the filtered voltage is v_dc (1 - exp(-k T / tau)) k periods later, whether a frame was
    asked for every period or, later, only now and then."""
    tau = 0.7e-3
    p = quiet(sensors={"terminal": {"filter_time_constant_s": tau}})
    plant = Plant(p)
    T = p.control_period_s
    vdc = p.dc_link.source_voltage_v
    f = plant.sensor_frame()
    assert (f.adc_va, f.adc_vb, f.adc_vc) == (0, 0, 0)
    for k in range(1, 80):
        plant.step(gates=V1)
        if k > 30 and k not in (33, 40, 52, 79):
            continue
        f = plant.sensor_frame()
        expected = vdc * (1.0 - math.exp(-k * T / tau))
        assert plant.sensors.terminal.filtered_v[0] == pytest.approx(expected, rel=1e-12, abs=1e-12)
        assert f.adc_va == math.floor(expected / p.sensors.terminal.v_per_count + 0.5)
        assert plant.sensors.terminal.filtered_v[1:] == [0.0, 0.0]
    assert "step" not in plant.__dict__         # frames add no period hook


def test_floating_phase_reads_star_point_plus_back_emf():
    """A spinning motor, leg a high, b low, c off: c carries nothing and its terminal is
    v_n + e_c = (v_dc - e_a - e_b)/2 + e_c (closed form), which is also the voltage the
    circuit's own constraint di_c/dt = 0 gives (Network.vx), both averaged over the period as
    the mean of its ends."""
    p = quiet(initial={"speed_rad_s": 120.0})
    plant = Plant(p)
    m = p.motor
    vdc = p.dc_link.source_voltage_v
    reference = Network(plant.motor, plant.inverter, plant.dc_link, plant.load)
    reference.ckernel = None
    reference._configure([H, L, O])

    def network_vx():
        s = plant.state
        reference.rhs(plant.t_s, s["psi_alpha"], s["psi_beta"], s["speed_rad_s"],
                      s["theta_m_rad"], vdc)
        return reference.vx

    plant.sensor_frame()
    seen = []
    for k in range(200):
        before = plant.truth()
        vx_start = network_vx()
        plant.step(gates=0x09)                      # A_HIGH | B_LOW
        after = plant.truth()
        f = plant.sensor_frame()
        assert abs(after[F["i_c"]]) < 1e-9
        e = [0.5 * (a + b) for a, b in zip(
            emf(m.flux_linkage_wb, m.pole_pairs, before[F["theta_m_rad"]], before[F["speed_rad_s"]]),
            emf(m.flux_linkage_wb, m.pole_pairs, after[F["theta_m_rad"]], after[F["speed_rad_s"]]))]
        analytic = (vdc + 0.0 - e[0] - e[1]) / 2.0 + e[2]
        v = plant.sensors.terminal.filtered_v
        assert v[:2] == [vdc, 0.0]
        assert v[2] == pytest.approx(analytic, abs=1e-9), k
        assert v[2] == pytest.approx(0.5 * (vx_start + network_vx()), abs=1e-9), k
        assert f.adc_vc == math.floor(analytic / p.sensors.terminal.v_per_count + 0.5)
        seen.append(v[2])
    assert max(seen) - min(seen) > 5.0      # the back-EMF moved the floating terminal


def test_floated_duty_leg_under_a_period_hook_reads_the_star_point():
    """DUTY_LEGS with leg c floated, on a plant whose thermal model hooks every step, rotor
    locked (no back-EMF: with one, a floated leg's diodes conduct whenever a and b are both
    high or both low): a and b average d v_dc over the period, c the star point
    (d_a + d_b) v_dc / 2."""
    p = quiet(load={"locked": True}, thermal={"enabled": True})
    plant = Plant(p)
    vdc = p.dc_link.source_voltage_v
    plant.sensor_frame()
    for k in range(50):
        plant.step(duty=(0.7, 0.2, 0.5), legs=0b011)
        plant.sensor_frame()
        v = plant.sensors.terminal.filtered_v
        assert abs(plant.truth()[F["i_c"]]) < 1e-9
        assert plant.truth()[F["i_a"]] > 0.1 * (k + 1) / 50
        assert v == pytest.approx([0.7 * vdc, 0.2 * vdc, 0.45 * vdc], rel=1e-14), k


def test_bemf_comparators_flip_where_the_closed_form_says():
    """All legs off, coasting below the link voltage: terminal x minus the virtual neutral is
    e_x (sum e = 0), so comparator x reads 1 iff e_x > offset_x: it turns on where
    sin(theta_e - n_x 120 deg) = -offset_x / (omega_e psi), i.e. at phase angle pi + asin(...)."""
    offsets = [0.8, -1.5, 2.5]
    p = quiet(initial={"speed_rad_s": 100.0},
              sensors={"terminal": {"comparator_offset_v": offsets}})
    plant = Plant(p)
    m = p.motor
    T = p.control_period_s
    plant.sensor_frame()
    ons = [[] for _ in range(3)]
    prev_bits = plant.sensor_frame().bemf_comparators
    for k in range(round(2.2 * math.pi / 100.0 / T)):
        before = plant.truth()
        plant.step()
        after = plant.truth()
        bits = plant.sensor_frame().bemf_comparators
        e0 = emf(m.flux_linkage_wb, m.pole_pairs, before[F["theta_m_rad"]], before[F["speed_rad_s"]])
        e1 = emf(m.flux_linkage_wb, m.pole_pairs, after[F["theta_m_rad"]], after[F["speed_rad_s"]])
        for x in range(3):
            e_mean = 0.5 * (e0[x] + e1[x])
            assert bool(bits >> x & 1) == (e_mean > offsets[x]), (k, x)
            if bits >> x & 1 and not prev_bits >> x & 1:
                ons[x].append((before[F["theta_e_rad"]] - x * THIRD,
                               after[F["theta_e_rad"]] - x * THIRD, after[F["speed_rad_s"]]))
        prev_bits = bits
    for x in range(3):
        assert ons[x], x
        for phi0, phi1, w in ons[x]:
            # the bit sees e averaged over the period: it turns on in the period whose middle
            # passes the crossing (e's mean over the ends: sin(middle) cos(omega_e T / 2))
            crossing = math.pi + math.asin(offsets[x] / (m.pole_pairs * w * m.flux_linkage_wb))
            middle = 0.5 * (phi0 + phi1)
            late = math.remainder(middle - crossing, 2 * math.pi)
            assert -1e-6 <= late <= m.pole_pairs * w * T + 1e-6, (x, late)
    plant.sensors.terminal.comparator_stuck[:] = [1, None, 0]
    plant.step()
    assert plant.sensor_frame().bemf_comparators & 0b101 == 0b001


# ---------------------------------------------------------------------- currents
@pytest.mark.parametrize("build", [V1, V4])
def test_low_side_shunt_reads_the_current_iff_the_low_side_conducts(build):
    """Every gate word after a current was built up: phase x reads i_x when its low switch
    is on alone, 0 A when its high switch is on alone, and with both off (or both on: the
    driver trips the leg) i_x only while the low diode carries it (i_x > 0)."""
    p = quiet(sensors={"current": {"placement": "low_side"}})
    checked = {True: 0, False: 0}
    for word in range(64):
        plant = Plant(p)
        for _ in range(8):
            plant.step(gates=build)
        plant.step(gates=word)
        f = plant.sensor_frame()
        t = plant.truth()
        currents = (t[F["i_a"]], t[F["i_b"]], t[F["i_c"]])
        codes = (f.adc_ia, f.adc_ib, f.adc_ic)
        for x, state in enumerate(leg_states(word)):
            conducts = state == L or (state == O and currents[x] > 1e-9)
            read = currents[x] if conducts else 0.0
            assert codes[x] == math.floor(2048 + read / LSB_I + 0.5), (word, x)
            if abs(currents[x]) > 0.5:
                checked[conducts] += 1
    assert checked[True] > 20 and checked[False] > 20


def test_inline_shunts_read_every_phase_current():
    p = quiet(initial={"speed_rad_s": 50.0})
    plant = Plant(p)
    for k in range(30):
        plant.step(duty=(0.7, 0.3, 0.45))
        f = plant.sensor_frame()
        t = plant.truth()
        for code, name in zip((f.adc_ia, f.adc_ib, f.adc_ic), ("i_a", "i_b", "i_c")):
            assert code == math.floor(2048 + t[F[name]] / LSB_I + 0.5)


def test_sensor_frames_leave_the_sample_stream_unchanged():
    """The frame's channels draw their own noise: a plant asked for frames every period gives
    the very samples of one that never was, and its phase-a channel (the same transducer as
    SAMPLE's adc_i1) does not repeat adc_i1's noise."""
    p = load_profile(overrides={"initial": {"speed_rad_s": 80.0}})
    plain, framed = Plant(p, seed=7), Plant(p, seed=7)
    differ = 0
    for k in range(300):
        s = plain.sample()
        f = framed.sensor_frame()
        assert framed.sample() == s
        differ += f.adc_ia != s.adc_i1
        assert (f.period, f.status, f.adc_vdc, f.encoder) == (s.period, s.status, s.adc_vdc,
                                                                s.encoder)
        duty = (0.5 + 0.3 * math.sin(k / 20), 0.5, 0.5 - 0.3 * math.sin(k / 20))
        plain.step(duty=duty)
        framed.step(duty=duty)
    assert isinstance(f, SensorFrame)
    assert differ > 50


# ---------------------------------------------------------------------- resolver
def resolver_profile(m: float, q_deg: float, **extra):
    return quiet(initial={"speed_rad_s": 90.0}, sensors={"resolver": {
        "pole_pairs": 3, "amplitude_counts": 30000.0, "offset_counts": 32768.0, "bits": 16,
        "amplitude_imbalance": m, "quadrature_error_deg": q_deg, **extra}})


def test_resolver_counts_follow_the_formula():
    m, q = 0.04, 3.0
    p = resolver_profile(m, q)
    plant = Plant(p)
    for k in range(400):
        f = plant.sensor_frame()
        th_r = 3 * plant.truth()[F["theta_m_rad"]]
        assert f.adc_resolver_sin == math.floor(32768 + 30000 * (1 + m / 2) * math.sin(th_r) + 0.5)
        assert f.adc_resolver_cos == math.floor(
            32768 + 30000 * (1 - m / 2) * math.cos(th_r - math.radians(q)) + 0.5)
        plant.step()


def test_resolver_atan2_error_matches_its_first_order_closed_form():
    """theta_hat - theta_r = (m/2) sin 2 theta_r - (q/2)(1 - cos 2 theta_r) to first order in
    the imbalance m and the quadrature error q."""
    m, q_deg = 0.01, 0.6
    q = math.radians(q_deg)
    p = resolver_profile(m, q_deg)
    plant = Plant(p)
    worst = 0.0
    for k in range(500):
        f = plant.sensor_frame()
        th_r = 3 * plant.truth()[F["theta_m_rad"]]
        est = math.atan2(f.adc_resolver_sin - 32768, f.adc_resolver_cos - 32768)
        error = math.remainder(est - th_r, 2 * math.pi)
        first_order = 0.5 * m * math.sin(2 * th_r) - 0.5 * q * (1 - math.cos(2 * th_r))
        # second order: (m^2 + q^2) terms; rounding: half a count in 30000
        assert error == pytest.approx(first_order, abs=(m * m + q * q) + 2.5e-5), k
        worst = max(worst, abs(first_order))
        plant.step()
    assert worst > 10 * (m * m + q * q + 2.5e-5)      # the effect is well above the tolerance


# ----------------------------------------------------------------------- thermal
def test_thermal_model_under_constant_loss_is_first_order():
    params = ThermalParams(enabled=True, thermal_resistance_k_per_w=1.5,
                           thermal_capacitance_j_per_k=0.02, ambient_degc=30.0, initial_degc=30.0)
    T = 50e-6
    model = ThermalModel(params, 0.5, T)
    loss = 12.0
    for k in range(1, 2001):
        model.advance(loss)
        tau = 1.5 * 0.02
        assert model.temperature_degc == pytest.approx(
            30.0 + loss * 1.5 * (1.0 - math.exp(-k * T / tau)), rel=1e-12)


def locked_profile(alpha: float, vdc: float):
    return quiet(dc_link={"source_voltage_v": vdc}, load={"locked": True},
                 thermal={"enabled": True, "thermal_resistance_k_per_w": 2.0,
                          "thermal_capacitance_j_per_k": 0.05, "copper_alpha_per_k": alpha,
                          "ambient_degc": 25.0, "initial_degc": 25.0, "reference_degc": 20.0})


def test_plant_winding_heats_as_the_closed_form_under_constant_copper_loss():
    """Locked rotor, V1 held: the current settles to i_a = (2/3 v_dc)/R, so P = 3/2 R i_a^2
    is constant and T(t) = T_inf + (T(t1) - T_inf) exp(-(t - t1)/(R_th C_th)) from then on."""
    vdc = 1.0
    p = locked_profile(0.0, vdc)
    plant = Plant(p)
    T = p.control_period_s
    r = p.motor.resistance_ohm
    settle = round(0.4 / T)                 # 39 L/R: the current is constant to 1e-16
    for _ in range(settle):
        plant.step(gates=V1)
    start = plant.winding_temperature_degc
    loss = 1.5 * r * (2.0 / 3.0 * vdc / r) ** 2
    t_inf = 25.0 + loss * 2.0
    assert start > 25.0 + 0.5 * (t_inf - 25.0)
    for k in range(1, 2001):
        plant.step(gates=V1)
        expected = t_inf + (start - t_inf) * math.exp(-k * T / 0.1)
        assert plant.winding_temperature_degc == pytest.approx(expected, abs=2e-9), k
    f = plant.sensor_frame()
    assert f.adc_temperature == math.floor(plant.winding_temperature_degc / 0.1 + 0.5)


def test_plant_resistance_follows_the_winding_temperature():
    """R = R_ref (1 + alpha (T - T_ref)) to 1e-6 while T follows C dT/dt = P - (T - T_amb)/R_th
    with P = 3/2 R |i_alphabeta|^2 of the true currents (a reference recursion here)."""
    alpha = 0.00393
    p = locked_profile(alpha, 5.0)
    plant = Plant(p)
    T = p.control_period_s
    r_ref = p.motor.resistance_ohm
    decay = math.exp(-T / 0.1)
    temp = 25.0
    assert plant.motor.r == pytest.approx(r_ref * (1 + alpha * 5.0), rel=1e-12)
    for k in range(4000):
        plant.step(gates=V1)
        t = plant.truth()
        r_k = r_ref * (1 + alpha * (temp - 20.0))
        loss = 1.5 * r_k * (t[F["i_alpha"]] ** 2 + t[F["i_beta"]] ** 2)
        temp = 25.0 + loss * 2.0 + (temp - 25.0 - loss * 2.0) * decay
        assert plant.winding_temperature_degc == pytest.approx(temp, rel=1e-9), k
        assert plant.motor.r == pytest.approx(r_ref * (1 + alpha * (temp - 20.0)), rel=1.01e-6)
    assert plant.motor.r > 1.1 * r_ref


def test_without_a_thermal_section_nothing_changes():
    plant = Plant(quiet())
    for _ in range(10):
        plant.step(gates=V1)
    assert plant.winding_temperature_degc == 25.0
    assert plant.motor.r == load_profile().motor.resistance_ohm
    assert "step" not in plant.__dict__       # no period hook: today's step()


# ----------------------------------------------------------------------- profile
@pytest.mark.parametrize("section, value, words", [
    ({"hall": {"placement_error_deg": [1.0, 2.0]}}, None, "three numbers"),
    ({"hall": {"placement_error_deg": [1.0, float("nan"), 0.0]}}, None, "finite"),
    ({"hall": {"hysteresis_deg": -1.0}}, None, ">= 0"),
    ({"terminal": {"comparator_offset_v": 0.5}}, None, "three numbers"),
    ({"terminal": {"filter_time_constant_s": float("inf")}}, None, "finite"),
    ({"current": {"placement": "high_side"}}, None, "inline, low_side"),
    ({"resolver": {"pole_pairs": 0}}, None, ">= 1"),
])
def test_bad_sensor_set_keys_are_refused_naming_the_key(section, value, words):
    with pytest.raises(ConfigError) as err:
        load_profile(overrides={"sensors": section})
    assert words in str(err.value)
    key = next(iter(section))
    assert key in str(err.value)


def test_bad_thermal_key_is_refused():
    with pytest.raises(ConfigError, match="thermal_capacitance_j_per_k"):
        load_profile(overrides={"thermal": {"thermal_capacitance_j_per_k": 0.0}})


def test_stuck_levels_are_checked_where_a_fault_sets_them():
    plant = Plant(quiet())
    for levels in (plant.sensors.hall.stuck, plant.sensors.terminal.comparator_stuck):
        for bad in (2, -1, 0.5, "1"):
            with pytest.raises(ValueError, match="None, 0 or 1"):
                levels[0] = bad
        with pytest.raises(ValueError, match="exactly three"):
            levels[:] = [1, 1]
        with pytest.raises(TypeError):
            levels.append(1)
        assert list(levels) == [None, None, None]
        levels[2] = 1
        assert list(levels) == [None, None, 1]
