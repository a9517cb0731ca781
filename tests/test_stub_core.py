"""The stub's control-core blocks through ctypes (build/libhilstub.so) against a
short Python reference of the same equations of Liu, Zhu, Howe: Clarke (8)-(9),
the flux observer (3)-(4) with its drift compensation, the hysteresis
comparators, the sector and switching table (Table 3), the PI speed regulator
with anti-windup, and the simplified EKF (20)-(23), including its tracking of a
rotating unit vector."""
from __future__ import annotations

import ctypes as C
import math

import numpy as np
import pytest

from hil.links.stub_library import load_library

T = 50e-6
A_PER_COUNT = 0.01220703125
F32 = C.c_float


class ClarkeCfg(C.Structure):
    _fields_ = [("current_a_per_count", F32), ("current_offset_counts", F32), ("phases", C.c_uint8),
                ("offset1_counts", F32), ("offset2_counts", F32),
                ("a1", F32), ("a2", F32), ("b1", F32), ("b2", F32)]


class ClarkeOut(C.Structure):
    _fields_ = [("i_alpha_a", F32), ("i_beta_a", F32), ("i_peak_a", F32)]


class HystCfg(C.Structure):
    _fields_ = [("band", F32), ("half_band", F32)]


class HystState(C.Structure):
    _fields_ = [("out", C.c_uint8)]


class SpiCfg(C.Structure):
    _fields_ = [("kp_nm_per_rad_s", F32), ("ki_nm_per_rad", F32), ("torque_limit_nm", F32),
                ("control_period_s", F32), ("ki_per_step_nm_per_rad_s", F32)]


class SpiState(C.Structure):
    _fields_ = [("integral_nm", F32)]


class FluxCfg(C.Structure):
    _fields_ = [("stator_resistance_ohm", F32), ("stator_inductance_h", F32), ("magnet_flux_wb", F32),
                ("control_period_s", F32), ("drift_cutoff_hz", F32), ("magnet_flux_sq_wb2", F32),
                ("drift_gain_per_step", F32), ("half_r_t_ohm_s", F32)]


class FluxState(C.Structure):
    _fields_ = [("psi_alpha_wb", F32), ("psi_beta_wb", F32), ("i_alpha_prev_a", F32), ("i_beta_prev_a", F32)]


class EkfCfg(C.Structure):
    _fields_ = [("control_period_s", F32), ("k1", F32), ("k2_rad_s", F32), ("k3_rad_s", F32)]


class EkfState(C.Structure):
    _fields_ = [("theta_rad", F32), ("speed_rad_s", F32), ("speed_increment_rad_s", F32),
                ("theta_filtered_rad", F32)]


def _bind(lib: C.CDLL) -> C.CDLL:
    P = C.POINTER
    sig = {
        "clarke_derive": (None, [P(ClarkeCfg)]),
        "clarke_from_adc": (None, [P(ClarkeCfg), C.c_uint16, C.c_uint16, P(ClarkeOut)]),
        "hyst_derive": (None, [P(HystCfg)]),
        "hyst_step": (C.c_uint8, [P(HystCfg), P(HystState), F32, F32]),
        "spi_derive": (None, [P(SpiCfg)]),
        "spi_step": (F32, [P(SpiCfg), P(SpiState), F32, F32]),
        "fluxobs_derive": (None, [P(FluxCfg)]),
        "fluxobs_reset": (None, [P(FluxState), F32, F32, F32, F32]),
        "fluxobs_step": (None, [P(FluxCfg), P(FluxState), F32, F32, F32, F32]),
        "flux_magnitude": (F32, [F32, F32]),
        "torque_estimate": (F32, [F32, F32, F32, F32, F32]),
        "ekf_reset": (None, [P(EkfState), F32, F32]),
        "ekf_step": (None, [P(EkfCfg), P(EkfState), F32, F32]),
        "ekf_step_angle": (None, [P(EkfCfg), P(EkfState), F32]),
        "swtab_sector": (C.c_uint8, [F32, F32]),
        "swtab_vector": (C.c_uint8, [C.c_uint8, C.c_uint8, C.c_uint8]),
        "vsi_gates_of_vector": (C.c_uint8, [C.c_uint8]),
        "vsi_voltage": (None, [C.c_uint8, F32, P(F32), P(F32)]),
        "fm_atan2": None,  # inline in the header: not exported
    }
    for name, s in sig.items():
        if s is None:
            continue
        fn = getattr(lib, name)
        fn.restype, fn.argtypes = s
    return lib


@pytest.fixture(scope="module")
def lib() -> C.CDLL:
    return _bind(load_library())


def f32(x: float) -> float:
    return float(np.float32(x))


# ------------------------------------------------------------- reference

def ref_clarke(adc1: int, adc2: int, phases: int) -> tuple[float, float]:
    """eq. (8)-(9) with i_a + i_b + i_c = 0 for the measured pair."""
    i1 = (adc1 - 2048.0) * A_PER_COUNT
    i2 = (adc2 - 2048.0) * A_PER_COUNT
    ia, ib = {0: (i1, i2), 1: (i1, -i1 - i2), 2: (-i1 - i2, i1)}[phases]
    return ia, (ia + 2.0 * ib) / math.sqrt(3.0)


def ref_hyst(band: float, out: int, ref: float, value: float) -> int:
    if value < ref - band / 2:
        return 1
    if value > ref + band / 2:
        return 0
    return out


def ref_pi(kp: float, ki: float, lim: float, integral: float, e: float) -> tuple[float, float]:
    """PI with conditional integration: hold the integrator while saturated and pushed further."""
    p = kp * e
    cand = integral + ki * T * e
    unsat = p + cand
    if unsat > lim and e > 0:
        return lim, integral
    if unsat < -lim and e < 0:
        return -lim, integral
    cand = min(max(cand, -lim), lim)
    return min(max(p + cand, -lim), lim), cand


def ref_flux_step(psi, i_prev, u, i, cutoff_hz, r=0.466, ls=4.8e-3, psi_f=0.0928):
    """eq. (3)-(4), trapezoidal R i, plus (gamma/2) eta (psi_f^2 - |eta|^2), eta = psi - Ls i_prev."""
    eta = psi - ls * i_prev
    k = T * 2 * math.pi * cutoff_hz / psi_f**2 * (psi_f**2 - eta @ eta)
    return psi + T * (u - r * 0.5 * (i + i_prev)) + k * eta


# Table 3 as printed in the paper: columns (flux, torque) = (1,1), (1,0), (0,1), (0,0)
TABLE3 = {1: (2, 6, 3, 5), 2: (3, 1, 4, 6), 3: (4, 2, 5, 1), 4: (5, 3, 6, 2), 5: (6, 4, 1, 3), 6: (1, 5, 2, 4)}
# Table 2 switching states (a, b, c)
STATES = {1: (1, 0, 0), 2: (1, 1, 0), 3: (0, 1, 0), 4: (0, 1, 1), 5: (0, 0, 1), 6: (1, 0, 1)}


def ref_sector(pa: float, pb: float) -> int:
    """Sector k spans (k - 1) 60 degrees +- 30 (Fig. 2)."""
    return int(math.floor((math.degrees(math.atan2(pb, pa)) + 30.0) / 60.0)) % 6 + 1


def ref_ekf(k1, k2, k3, state, y1, y2):
    """eq. (20)-(23); state (theta, w, w')."""
    th, w, wp = state
    eps = y2 * math.cos(th) - y1 * math.sin(th)
    return (math.remainder(th + T * w + k1 * eps, 2 * math.pi), w + wp + k2 * eps, wp + k3 * eps)


# ------------------------------------------------------------------ tests

@pytest.mark.parametrize("phases", [0, 1, 2])
def test_clarke_matches_reference(lib, phases):
    cfg = ClarkeCfg(A_PER_COUNT, 2048.0, phases)
    lib.clarke_derive(C.byref(cfg))
    out = ClarkeOut()
    rng = np.random.default_rng(1)
    for adc1, adc2 in rng.integers(0, 4096, size=(500, 2)):
        lib.clarke_from_adc(C.byref(cfg), int(adc1), int(adc2), C.byref(out))
        ia, ib = ref_clarke(int(adc1), int(adc2), phases)
        assert out.i_alpha_a == pytest.approx(ia, abs=1e-5)
        assert out.i_beta_a == pytest.approx(ib, abs=1e-5)


def test_hysteresis_matches_reference(lib):
    cfg = HystCfg(0.1)
    lib.hyst_derive(C.byref(cfg))
    st = HystState(1)
    out = 1
    values = 0.3 * np.sin(np.linspace(0, 60, 2000)) + 0.02 * np.random.default_rng(2).standard_normal(2000)
    toggles = 0
    for v in values:
        got = lib.hyst_step(C.byref(cfg), C.byref(st), 0.05, float(v))
        new = ref_hyst(f32(0.1), out, 0.05, f32(v))
        toggles += new != out
        out = new
        assert got == out
    assert toggles > 10


def test_switching_table_is_table3(lib):
    for sector, row in TABLE3.items():
        for col, vector in enumerate(row):
            assert lib.swtab_vector(sector, col < 2, col % 2 == 0) == vector
        # the gate bits of each vector are its Table 2 switching state, legs complementary
    for v, (sa, sb, sc) in STATES.items():
        g = lib.vsi_gates_of_vector(v)
        assert g == sa * 0x01 + (1 - sa) * 0x02 + sb * 0x04 + (1 - sb) * 0x08 + sc * 0x10 + (1 - sc) * 0x20


def test_sector_matches_angle(lib):
    rng = np.random.default_rng(3)
    for th, r in zip(rng.uniform(-math.pi, math.pi, 2000), rng.uniform(1e-3, 1.0, 2000)):
        if abs(math.remainder(math.degrees(th) - 30.0, 60.0)) < 1e-3:
            continue  # on a boundary
        pa, pb = f32(r * math.cos(th)), f32(r * math.sin(th))
        assert lib.swtab_sector(pa, pb) == ref_sector(pa, pb)


def test_table_vectors_move_flux_as_fig2(lib):
    """Each chosen vector (Table 2 voltage) moves |psi| and the flux angle as its column says."""
    ua, ub = F32(), F32()
    for th in np.radians(np.arange(-179.5, 180, 1.0)):
        pa, pb = math.cos(th), math.sin(th)
        sector = lib.swtab_sector(pa, pb)
        for flux_up in (0, 1):
            for torque_up in (0, 1):
                v = lib.swtab_vector(sector, flux_up, torque_up)
                lib.vsi_voltage(lib.vsi_gates_of_vector(v), 70.0, C.byref(ua), C.byref(ub))
                along = ua.value * pa + ub.value * pb
                across = -ua.value * pb + ub.value * pa
                assert (along > 0) == bool(flux_up)
                assert (across > 0) == bool(torque_up)


def test_pi_anti_windup_matches_reference(lib):
    cfg = SpiCfg(0.05, 0.8, 2.0, T)
    lib.spi_derive(C.byref(cfg))
    st = SpiState(0.0)
    integral = 0.0
    # a large step (saturates), an overshoot (unwinds), small errors (linear)
    errors = [60.0] * 3000 + [-3.0] * 3000 + list(5 * np.sin(np.linspace(0, 30, 3000)))
    saturated = 0
    for e in errors:
        got = lib.spi_step(C.byref(cfg), C.byref(st), float(e), 0.0)
        want, integral = ref_pi(f32(0.05), f32(0.8), 2.0, integral, f32(e))
        saturated += abs(want) == 2.0
        assert got == pytest.approx(want, abs=2e-5)
        assert st.integral_nm == pytest.approx(integral, abs=2e-5)
        assert abs(st.integral_nm) <= 2.0
    assert 100 < saturated < len(errors)


@pytest.mark.parametrize("cutoff_hz", [0.0, 10.0])
def test_flux_observer_matches_reference(lib, cutoff_hz):
    cfg = FluxCfg(0.466, 4.8e-3, 0.0928, T, cutoff_hz)
    lib.fluxobs_derive(C.byref(cfg))
    st = FluxState()
    psi = np.array([0.0928, 0.0])
    i_prev = np.zeros(2)
    lib.fluxobs_reset(C.byref(st), 0.0928, 0.0, 0.0, 0.0)
    rng = np.random.default_rng(4)
    for k in range(4000):
        v = rng.integers(1, 7)
        sa, sb, sc = STATES[int(v)]
        u = 70.0 * np.array([(2 * sa - sb - sc) / 3, (sb - sc) / math.sqrt(3)])
        i = np.array([8 * math.cos(0.01 * k), 8 * math.sin(0.01 * k)]) + rng.normal(0, 0.05, 2)
        lib.fluxobs_step(C.byref(cfg), C.byref(st), *map(float, u), *map(float, i))
        psi = ref_flux_step(psi, i_prev, u, i, cutoff_hz)
        i_prev = i
    # float32 against float64 over 4000 steps of a random walk
    assert st.psi_alpha_wb == pytest.approx(psi[0], abs=2e-5)
    assert st.psi_beta_wb == pytest.approx(psi[1], abs=2e-5)


def test_magnitude_and_torque_match_reference(lib):
    rng = np.random.default_rng(5)
    for pa, pb, ia, ib in rng.normal(0, [0.1, 0.1, 10, 10], size=(200, 4)):
        assert lib.flux_magnitude(pa, pb) == pytest.approx(math.hypot(pa, pb), rel=1e-6)
        assert lib.torque_estimate(1.0, pa, pb, ia, ib) == pytest.approx(1.5 * (pa * ib - pb * ia), abs=1e-5)


def _ekf_cfg() -> EkfCfg:
    from hil.design.ekf import default_gains

    g = default_gains()
    return EkfCfg(T, g.k1, g.k2_rad_s, g.k3_rad_s)


def test_ekf_update_matches_reference(lib):
    cfg = _ekf_cfg()
    st = EkfState()
    lib.ekf_reset(C.byref(st), 0.2, 50.0)
    ref = (f32(0.2), 50.0, 0.0)
    rng = np.random.default_rng(6)
    k1, k2, k3 = cfg.k1, cfg.k2_rad_s, cfg.k3_rad_s
    for k in range(3000):
        th = 100.0 * k * T + 0.3 * math.sin(0.002 * k) + rng.normal(0, 0.01)
        y1, y2 = math.cos(th), math.sin(th)
        lib.ekf_step(C.byref(cfg), C.byref(st), y1, y2)
        ref = ref_ekf(k1, k2, k3, ref, f32(y1), f32(y2))
        assert math.remainder(st.theta_rad - ref[0], 2 * math.pi) == pytest.approx(0.0, abs=2e-5)
        assert st.speed_rad_s == pytest.approx(ref[1], abs=2e-3)
        assert st.speed_increment_rad_s == pytest.approx(ref[2], abs=1e-4)


def test_ekf_angle_form_equals_normalised_flux_form(lib):
    """eps = y2 cos th^ - y1 sin th^ = sin(theta_s - th^): the control step's form is eq. (20)."""
    cfg = _ekf_cfg()
    a, b = EkfState(), EkfState()
    lib.ekf_reset(C.byref(a), 0.0, 0.0)
    lib.ekf_reset(C.byref(b), 0.0, 0.0)
    for k in range(4000):
        th = math.remainder(0.5 * 2500.0 * (k * T) ** 2 + 0.05 * math.sin(0.01 * k), 2 * math.pi)
        lib.ekf_step(C.byref(cfg), C.byref(a), math.cos(th), math.sin(th))
        lib.ekf_step_angle(C.byref(cfg), C.byref(b), th)
        assert a.speed_rad_s == pytest.approx(b.speed_rad_s, abs=1e-2)
        assert math.remainder(a.theta_rad - b.theta_rad, 2 * math.pi) == pytest.approx(0.0, abs=1e-5)


def _track(lib, speed_of_t, initial_speed, seconds, noise_rad=0.0, seed=7):
    """Runs the EKF on a rotating unit vector at speed_of_t(t) (electrical rad/s); returns
    arrays of true speed, estimated speed and angle error."""
    cfg = _ekf_cfg()
    st = EkfState()
    lib.ekf_reset(C.byref(st), 0.0, initial_speed)
    rng = np.random.default_rng(seed)
    n = int(seconds / T)
    th = 0.0
    w_true, w_est, ang_err = np.empty(n), np.empty(n), np.empty(n)
    for k in range(n):
        meas = th + (rng.normal(0, noise_rad) if noise_rad else 0.0)
        lib.ekf_step(C.byref(cfg), C.byref(st), math.cos(meas), math.sin(meas))
        th += speed_of_t((k + 0.5) * T) * T  # midpoint: exact for a ramp
        # the model's w(k+1) is the mean speed over period k+1 (theta(k+2) - theta(k+1)) / T
        w_true[k] = speed_of_t((k + 1.5) * T)
        w_est[k] = st.speed_rad_s
        ang_err[k] = math.remainder(st.theta_rad - th, 2 * math.pi)
    return w_true, w_est, ang_err


@pytest.mark.parametrize("speed", [50.0, 314.16, -200.0])
def test_ekf_tracks_constant_speed(lib, speed):
    w_true, w_est, ang = _track(lib, lambda t: speed, speed, 0.1, noise_rad=0.01)
    tail = slice(len(w_true) // 2, None)
    # measurement noise 0.01 rad passes to the speed through the 570 rad/s estimator
    assert np.max(np.abs(w_est[tail] - w_true[tail])) < 10.0
    assert abs(np.mean(w_est[tail] - w_true[tail])) < 0.5
    assert np.max(np.abs(ang[tail])) < 0.02


def test_ekf_tracks_speed_ramp(lib):
    """The torque limit's acceleration (2 Nm / 8e-4 kg m^2): a type-3 loop has no lag on a ramp."""
    w_true, w_est, ang = _track(lib, lambda t: 2500.0 * t, 0.0, 0.2)
    tail = slice(len(w_true) // 4, None)
    assert np.max(np.abs(w_est[tail] - w_true[tail])) < 0.02
    assert np.max(np.abs(ang[tail])) < 1e-4


@pytest.mark.parametrize("initial", [0.0, 150.0, -314.0])
def test_ekf_converges_from_wrong_initial_speed(lib, initial):
    w_true, w_est, ang = _track(lib, lambda t: 314.16, initial, 0.1)
    err = np.abs(w_est - w_true)
    assert err[0] > 100.0 or initial == 150.0
    # settled within 40 ms (about 20 time constants of the 570 rad/s estimator), stays settled
    assert np.max(err[int(0.04 / T):]) < 0.1
    assert np.max(np.abs(ang[int(0.04 / T):])) < 1e-3
