"""A Python reference of the stub's FOC blocks (firmware_stub/core/svpwm.c,
current_pi.c, foc.c), checked against the C in the shared library, and the
FOC answering DUTY through the application layer.

The reference is written from the equations (docs/stub.md, FOC section) in
float64: SVPWM with the min-max zero sequence d_x = 1/2 + (v_x + v0)/Vdc, the
linear-range circle |u| <= Vdc/sqrt3, dead-time compensation Td/T sign(i_x)
(linear inside the band), the d-q PI with Kp = Ls wc, Ki = R wc, decoupling
feed-forward and conditional integration, Park and the inverse Park at
theta + w T/2. The C runs float32 with polynomial sincos (1.5e-7 rad), so
the comparisons allow float32 rounding.
"""
from __future__ import annotations

import ctypes
import math

import numpy as np
import pytest

from hil.links.stub_library import StubLibraryLink, load_library
from protocol.messages import (CMD_ENABLE, Command, Duty, Gates, ParamId, ParamSet, ParamStatus,
                               ParamValue, Sample, SpeedSource)

F = ctypes.c_float


class CpiCfg(ctypes.Structure):
    _fields_ = [(n, F) for n in ("bandwidth_hz", "r", "ls", "psi_f", "t", "kp", "ki", "ki_step")]


class CpiState(ctypes.Structure):
    _fields_ = [("int_d", F), ("int_q", F)]


class CpiOut(ctypes.Structure):
    _fields_ = [("u_d", F), ("u_q", F), ("limited", ctypes.c_int)]


class SvpwmCfg(ctypes.Structure):
    _fields_ = [(n, F) for n in ("t", "td", "band", "td_duty", "td_duty_per_a")]


class FocCfg(ctypes.Structure):
    _fields_ = [("current", CpiCfg), ("pwm", SvpwmCfg), ("pole_pairs", F), ("t", F),
                ("amp_per_nm", F), ("half_t", F)]


class FocState(ctypes.Structure):
    _fields_ = [("current", CpiState), ("i_d", F), ("i_q", F), ("i_q_ref", F), ("u_alpha", F),
                ("u_beta", F), ("limited", ctypes.c_uint8)]


R, LS, PSI_F, T = 0.466, 4.8e-3, 0.0928, 50e-6
SQRT3 = math.sqrt(3.0)


@pytest.fixture(scope="module")
def lib():
    lib = load_library()
    P = ctypes.POINTER
    lib.svpwm_duties.argtypes = [F, F, F, P(F)]
    lib.svpwm_limit.argtypes = [F, P(F), P(F)]
    lib.svpwm_limit.restype = ctypes.c_int
    lib.svpwm_derive.argtypes = [P(SvpwmCfg)]
    lib.svpwm_dead_time_comp.argtypes = [P(SvpwmCfg), P(F), P(F)]
    lib.svpwm_duty_u16.argtypes = [F]
    lib.svpwm_duty_u16.restype = ctypes.c_uint16
    lib.cpi_derive.argtypes = [P(CpiCfg)]
    lib.cpi_step.argtypes = [P(CpiCfg), P(CpiState), F, F, F, F, F, F, P(CpiOut)]
    lib.foc_derive.argtypes = [P(FocCfg)]
    lib.foc_reset.argtypes = [P(FocState)]
    lib.foc_step.argtypes = [P(FocCfg), P(FocState), F, F, F, F, F, F, P(F)]
    return lib


# ---------------------------------------------------------------- reference

def ref_svpwm(ua, ub, vdc):
    v = np.array([ua, -ua / 2 + SQRT3 / 2 * ub, -ua / 2 - SQRT3 / 2 * ub])
    v0 = -(v.max() + v.min()) / 2
    return 0.5 + (v + v0) / vdc


def ref_limit(ua, ub, vdc):
    umax, mag = vdc / SQRT3, math.hypot(ua, ub)
    return (ua, ub) if mag <= umax else (ua * umax / mag, ub * umax / mag)


def ref_dead_time(duty, i_abc, td_duty, band):
    comp = np.clip(np.asarray(i_abc) / band * td_duty, -td_duty, td_duty)
    return np.clip(duty + comp, 0.0, 1.0)


class RefCurrentPi:
    def __init__(self, bandwidth_hz):
        wc = 2 * math.pi * bandwidth_hz
        self.kp, self.ki = LS * wc, R * wc
        self.int_d = self.int_q = 0.0

    def step(self, i_d, i_q, d_ref, q_ref, w, umax):
        e_d, e_q = d_ref - i_d, q_ref - i_q
        cd = float(np.clip(self.int_d + self.ki * T * e_d, -umax, umax))
        cq = float(np.clip(self.int_q + self.ki * T * e_q, -umax, umax))
        u_d = self.kp * e_d + cd - w * LS * i_q
        u_q = self.kp * e_q + cq + w * (LS * i_d + PSI_F)
        mag = math.hypot(u_d, u_q)
        limited = mag > umax
        if limited:
            u_d, u_q = u_d * umax / mag, u_q * umax / mag
            if e_d * u_d < 0:
                self.int_d = cd
            if e_q * u_q < 0:
                self.int_q = cq
        else:
            self.int_d, self.int_q = cd, cq
        return u_d, u_q, limited


def ref_foc(pi, theta, w, i_alpha, i_beta, torque, vdc):
    c, s = math.cos(theta), math.sin(theta)
    i_d, i_q = c * i_alpha + s * i_beta, c * i_beta - s * i_alpha
    u_d, u_q, _ = pi.step(i_d, i_q, 0.0, torque / (1.5 * PSI_F), w, vdc / SQRT3)
    th = theta + w * T / 2
    ua = math.cos(th) * u_d - math.sin(th) * u_q
    ub = math.sin(th) * u_d + math.cos(th) * u_q
    ua, ub = ref_limit(ua, ub, vdc)
    return ref_svpwm(ua, ub, vdc), (i_d, i_q), (ua, ub)


# ---------------------------------------------------------------- checks

def test_svpwm_and_limit_match_the_reference(lib):
    rng = np.random.default_rng(1)
    out = (F * 3)()
    for _ in range(2000):
        vdc = rng.uniform(20, 90)
        ua, ub = rng.uniform(-vdc, vdc, 2)
        a, b = F(ua), F(ub)
        limited = lib.svpwm_limit(vdc, ctypes.byref(a), ctypes.byref(b))
        ra, rb = ref_limit(float(F(ua).value), float(F(ub).value), float(F(vdc).value))
        assert limited == (math.hypot(ua, ub) > vdc / SQRT3) or abs(math.hypot(ua, ub) - vdc / SQRT3) < 1e-4
        assert a.value == pytest.approx(ra, abs=2e-5 * vdc)
        assert b.value == pytest.approx(rb, abs=2e-5 * vdc)
        lib.svpwm_duties(a, b, vdc, out)
        assert np.allclose(list(out), ref_svpwm(a.value, b.value, F(vdc).value), atol=2e-6)


def test_dead_time_compensation_and_quantisation_match(lib):
    cfg = SvpwmCfg(T, 1.5e-6, 0.1)
    lib.svpwm_derive(ctypes.byref(cfg))
    rng = np.random.default_rng(2)
    for _ in range(1000):
        duty = rng.uniform(-0.02, 1.02, 3)
        i = rng.uniform(-0.3, 0.3, 3)
        d = (F * 3)(*duty)
        lib.svpwm_dead_time_comp(ctypes.byref(cfg), (F * 3)(*i), d)
        assert np.allclose(list(d), ref_dead_time(np.float32(duty), np.float32(i), 0.03, 0.1), atol=1e-6)
        for x in d:
            # float32 product plus one half, truncated: round to nearest in float32
            q = int(np.float32(x) * np.float32(65535) + np.float32(0.5)) if 0 < x < 1 else (65535 if x >= 1 else 0)
            assert lib.svpwm_duty_u16(x) == q


def test_current_pi_sequence_matches_the_reference(lib):
    """A stateful sequence through saturation and back: the integrators of C and
    the reference must stay together, limit decisions included."""
    cfg = CpiCfg(1000.0, R, LS, PSI_F, T)
    lib.cpi_derive(ctypes.byref(cfg))
    assert cfg.kp == pytest.approx(LS * 2 * math.pi * 1000, rel=1e-6)
    assert cfg.ki == pytest.approx(R * 2 * math.pi * 1000, rel=1e-6)
    st, out, ref = CpiState(), CpiOut(), RefCurrentPi(1000.0)
    rng = np.random.default_rng(3)
    limited_seen = 0
    for k in range(4000):
        big = (k // 500) % 2 == 1          # every other 25 ms far from the reference
        i_d, i_q = rng.normal(0, 0.5, 2)
        q_ref = 14.0 if big else rng.uniform(-1, 1)
        w = rng.uniform(-320, 320)
        lib.cpi_step(ctypes.byref(cfg), ctypes.byref(st), i_d, i_q, 0.0, q_ref, w, 40.4, ctypes.byref(out))
        args = [float(F(v).value) for v in (i_d, i_q, 0.0, q_ref, w, 40.4)]
        u_d, u_q, limited = ref.step(*args)
        assert bool(out.limited) == limited
        limited_seen += limited
        assert out.u_d == pytest.approx(u_d, abs=1e-4)
        assert out.u_q == pytest.approx(u_q, abs=1e-4)
        assert st.int_q == pytest.approx(ref.int_q, abs=1e-4)
        assert st.int_d == pytest.approx(ref.int_d, abs=1e-4)
    assert limited_seen > 100


def test_foc_step_matches_the_reference(lib):
    cfg = FocCfg()
    cfg.current = CpiCfg(1000.0, R, LS, PSI_F)
    cfg.pwm = SvpwmCfg(0.0, 0.0, 0.1)
    cfg.pole_pairs, cfg.t = 1.0, T
    lib.foc_derive(ctypes.byref(cfg))
    st = FocState()
    lib.foc_reset(ctypes.byref(st))
    ref = RefCurrentPi(1000.0)
    rng = np.random.default_rng(4)
    duty = (F * 3)()
    for _ in range(3000):
        theta, w = rng.uniform(-math.pi, math.pi), rng.uniform(-320, 320)
        ia, ib = rng.normal(0, 5, 2)
        torque, vdc = rng.uniform(-2, 2), rng.uniform(50, 80)
        lib.foc_step(ctypes.byref(cfg), ctypes.byref(st), theta, w, ia, ib, torque, vdc, duty)
        args = [float(F(v).value) for v in (theta, w, ia, ib, torque, vdc)]
        d_ref, (i_d, i_q), (ua, ub) = ref_foc(ref, *args)
        assert st.i_d == pytest.approx(i_d, abs=1e-5 * 15)
        assert st.i_q == pytest.approx(i_q, abs=1e-5 * 15)
        assert st.u_alpha == pytest.approx(ua, abs=2e-4)
        assert st.u_beta == pytest.approx(ub, abs=2e-4)
        assert np.allclose(list(duty), d_ref, atol=1e-5)


def _answers(link, msg):
    link.send(msg)
    out = []
    while (m := link.recv(0.0)) is not None:
        out.append(m)
    return out


def test_foc_answers_duty_through_the_application_layer():
    """CONTROL_LAW 1: SAMPLE -> DUTY while running, GATES 0 while idle; the
    default law keeps answering GATES."""
    with StubLibraryLink() as link:
        idle = _answers(link, Sample(0, 2048, 2048, 2867, 0, 0))
        assert [type(m) for m in idle if type(m) in (Gates, Duty)] == [Gates]
        assert _answers(link, ParamSet(ParamId.CONTROL_LAW, 1.0))[-1] == \
            ParamValue(ParamId.CONTROL_LAW, ParamStatus.OK, 1.0)
        _answers(link, Command(CMD_ENABLE, SpeedSource.ENCODER, 100.0, 0.0, 0.0))
        answer = [m for m in _answers(link, Sample(1, 2048, 2048, 2867, 0, 0)) if type(m) in (Gates, Duty)]
        assert len(answer) == 1 and type(answer[0]) is Duty and answer[0].period == 1
        d = answer[0].duty
        assert max(d) + min(d) == 65535      # centred pulses
        assert d[1] > d[2]                   # +q at theta_e = 0 is +beta: phase b above c
        _answers(link, ParamSet(ParamId.CONTROL_LAW, 0.0))
        answer = [m for m in _answers(link, Sample(2, 2048, 2048, 2867, 0, 0)) if type(m) in (Gates, Duty)]
        assert type(answer[0]) is Gates and answer[0].gates != 0
