"""Permanent-magnet synchronous machine: stator flux linkage, currents, torque and rotor motion.

State, all plain floats: stator flux linkage (psi_alpha, psi_beta) in the stationary frame,
mechanical speed w (rad/s) and mechanical angle theta_m (rad); theta_e = p * theta_m, with
theta_e = 0 when the magnet's d-axis lies along phase a.

    d psi/dt = u - R i                                   eq. (1)-(4), stationary frame
    psi_d = Ld i_d + psi_m,  psi_q = Lq i_q              rotor (d, q) frame at theta_e
    T = 1.5 p (psi_alpha i_beta - psi_beta i_alpha)      eq. (6)
      = 1.5 p (psi_m i_q + (Ld - Lq) i_d i_q)
    J dw/dt = T - B w - T_load,   d theta_m/dt = w

The flux linkage is the state because the inverter's voltage is piecewise constant in the
stationary frame: eq. (1) then integrates with no rotation of the input, Ld != Lq costs two
rotations per stage, and the currents and torque follow algebraically. Amplitude-invariant
Clarke transform as eq. (7): i_alpha = i_a, i_beta = (i_a + 2 i_b)/sqrt(3).
"""
from __future__ import annotations

from configfile.dataclass_methods import dataclass
import math
from math import cos, sin

from configfile.fields import param


@dataclass(frozen=True)
class MotorParams:
    """Machine constants; defaults are the paper's Table 1 (surface magnets, Ld = Lq = Ls)."""

    pole_pairs: int = param(1, ge=1)
    resistance_ohm: float = param(0.466, gt=0)
    flux_linkage_wb: float = param(0.0928, ge=0)
    inductance_d_h: float = param(4.8e-3, gt=0)
    inductance_q_h: float = param(4.8e-3, gt=0)
    inertia_kgm2: float = param(8.0e-4, gt=0)
    damping_nm_per_rad_s: float = param(1.0e-4, ge=0)
    rated_speed_rpm: float = param(3000.0, gt=0)


class MotorModel:
    """Derived constants and the stator/rotor maths on plain floats (no numpy: hot path)."""

    __slots__ = ("params", "p", "r", "psim", "ld", "lq", "ild", "ilq", "j", "ij", "b", "kt", "spm",
                 "_k")

    def __init__(self, params: MotorParams):
        self.set_params(params)

    def set_params(self, params: MotorParams) -> None:
        self.params = params
        self.p = params.pole_pairs
        self.r = params.resistance_ohm
        self.psim = params.flux_linkage_wb
        self.ld = params.inductance_d_h
        self.lq = params.inductance_q_h
        self.ild = 1.0 / self.ld
        self.ilq = 1.0 / self.lq
        self.j = params.inertia_kgm2
        self.ij = 1.0 / self.j
        self.b = params.damping_nm_per_rad_s
        self.kt = 1.5 * self.p
        self.spm = self.ld == self.lq
        # the C kernel's motor constants, in the order of its cfg_t (plant_rt/c/_plantnet.c):
        # pole_pairs, resistance_ohm, flux_linkage_wb, inv_ld_per_h, inv_lq_per_h,
        # inv_inertia_per_kgm2, damping_nm_per_rad_s, torque_coeff
        self._k = (float(self.p), self.r, self.psim, self.ild, self.ilq, self.ij, self.b, self.kt)

    # ----------------------------------------------------------------- algebra
    def currents(self, pa: float, pb: float, theta_m: float) -> tuple[float, float, float, float]:
        """(i_alpha, i_beta, i_d, i_q) from the flux linkage and the rotor angle."""
        e = self.p * theta_m
        c, s = cos(e), sin(e)
        i_d = (c * pa + s * pb - self.psim) * self.ild
        i_q = (c * pb - s * pa) * self.ilq
        return c * i_d - s * i_q, s * i_d + c * i_q, i_d, i_q

    def flux_from_currents(self, i_d: float, i_q: float, theta_m: float) -> tuple[float, float]:
        """Stationary-frame flux linkage of the given rotor-frame currents."""
        e = self.p * theta_m
        c, s = cos(e), sin(e)
        pd = self.ld * i_d + self.psim
        pq = self.lq * i_q
        return c * pd - s * pq, s * pd + c * pq

    def torque(self, i_d: float, i_q: float) -> float:
        """1.5 p (psi_m i_q + (Ld - Lq) i_d i_q): the rotor-frame form of eq. (6)."""
        return self.kt * (self.psim * i_q + (self.ld - self.lq) * i_d * i_q)

    # ------------------------------------------------------------ integration
    def advance(self, pa: float, pb: float, w: float, th: float, va: float, vb: float,
                h: float, n: int, tl0: float, tl_slope: float, bw: float
                ) -> tuple[float, float, float, float]:
        """n classic RK4 steps of length h with a constant stator voltage (va, vb).

        Load torque tl0 + tl_slope * t (t from the start) plus bw * w, bw = damping + the
        load's speed-proportional coefficient. Returns (psi_alpha, psi_beta, w, theta_m).
        One step per 50 us keeps the local error near 1e-10 of the state up to twice rated
        speed (omega_e h ~ 0.03 rad); freezing the angle over the step would not.
        """
        p, r, psim, ild, ilq, ij, _b, kt = self._k
        h2 = 0.5 * h
        h6 = h / 6.0
        t = 0.0
        if self.spm:
            # Ld = Lq = L: i = (psi - psi_m e_d)/L, so u - R i = u - (R/L) psi + (R psi_m/L) e_d
            # and the psi_m terms cancel out of eq. (6): T = 1.5 p psi_m/L (c psi_b - s psi_a).
            ril = r * ild
            rk = r * psim * ild
            kti = kt * psim * ild
            for _ in range(n):
                tl1 = tl0 + tl_slope * t
                tl2 = tl1 + tl_slope * h2
                tl4 = tl1 + tl_slope * h
                pa, pb, w, th = rk4_spm_step(p, ril, rk, kti, ij, bw, va, vb, h, tl1, tl2, tl4,
                                             pa, pb, w, th)
                t += h
            return pa, pb, w, th
        for _ in range(n):
            tl1 = tl0 + tl_slope * t
            tl2 = tl1 + tl_slope * h2
            tl4 = tl1 + tl_slope * h
            e = p * th
            c = cos(e)
            s = sin(e)
            pd = c * pa + s * pb
            pq = c * pb - s * pa
            i_d = (pd - psim) * ild
            i_q = pq * ilq
            d1a = va - r * (c * i_d - s * i_q)
            d1b = vb - r * (s * i_d + c * i_q)
            d1w = (kt * (pd * i_q - pq * i_d) - bw * w - tl1) * ij
            w2 = w + h2 * d1w
            e = p * (th + h2 * w)
            c = cos(e)
            s = sin(e)
            xa = pa + h2 * d1a
            xb = pb + h2 * d1b
            pd = c * xa + s * xb
            pq = c * xb - s * xa
            i_d = (pd - psim) * ild
            i_q = pq * ilq
            d2a = va - r * (c * i_d - s * i_q)
            d2b = vb - r * (s * i_d + c * i_q)
            d2w = (kt * (pd * i_q - pq * i_d) - bw * w2 - tl2) * ij
            w3 = w + h2 * d2w
            e = p * (th + h2 * w2)
            c = cos(e)
            s = sin(e)
            xa = pa + h2 * d2a
            xb = pb + h2 * d2b
            pd = c * xa + s * xb
            pq = c * xb - s * xa
            i_d = (pd - psim) * ild
            i_q = pq * ilq
            d3a = va - r * (c * i_d - s * i_q)
            d3b = vb - r * (s * i_d + c * i_q)
            d3w = (kt * (pd * i_q - pq * i_d) - bw * w3 - tl2) * ij
            w4 = w + h * d3w
            e = p * (th + h * w3)
            c = cos(e)
            s = sin(e)
            xa = pa + h * d3a
            xb = pb + h * d3b
            pd = c * xa + s * xb
            pq = c * xb - s * xa
            i_d = (pd - psim) * ild
            i_q = pq * ilq
            d4a = va - r * (c * i_d - s * i_q)
            d4b = vb - r * (s * i_d + c * i_q)
            d4w = (kt * (pd * i_q - pq * i_d) - bw * w4 - tl4) * ij
            pa += h6 * (d1a + 2.0 * (d2a + d3a) + d4a)
            pb += h6 * (d1b + 2.0 * (d2b + d3b) + d4b)
            th += h6 * (w + 2.0 * (w2 + w3) + w4)
            w += h6 * (d1w + 2.0 * (d2w + d3w) + d4w)
            t += h
        return pa, pb, w, th

    def advance_pieces(self, pa: float, pb: float, w: float, th: float, pieces: list,
                       h_max: float, tl0: float, tl_slope: float, bw: float
                       ) -> tuple[float, float, float, float, float]:
        """advance() over consecutive constant-voltage pieces [(h, va, vb, ga, gb), ...] in one
        call (a PWM period: up to seven), each integrated as it is by its own RK4 steps.

        Also returns int g . i dt over the pieces (g = (ga, gb) per piece, e.g. the DC-link
        current's phase weights), from eq. (1) exactly as RK4 integrated it:
        int_piece i dt = (u h - delta psi)/R.
        """
        p, r, psim, ild, ilq, ij, _b, kt = self._k
        t = 0.0
        q = 0.0
        spm = self.spm
        ril = r * ild
        rk = r * psim * ild
        kti = kt * psim * ild
        for length, va, vb, ga, gb in pieces:
            n = 1 if length <= h_max else max(1, math.ceil(length / h_max - 1e-9))
            pa0, pb0 = pa, pb
            if not spm:
                pa, pb, w, th = self.advance(pa, pb, w, th, va, vb, length / n, n,
                                             tl0 + tl_slope * t, tl_slope, bw)
            else:
                h = length / n
                h2 = 0.5 * h
                for i in range(n):
                    tl1 = tl0 + tl_slope * (t + i * h)
                    tl2 = tl1 + tl_slope * h2
                    tl4 = tl1 + tl_slope * h
                    pa, pb, w, th = rk4_spm_step(p, ril, rk, kti, ij, bw, va, vb, h, tl1, tl2,
                                                 tl4, pa, pb, w, th)
            if ga or gb:
                q += ga * (va * length - pa + pa0) + gb * (vb * length - pb + pb0)
            t += length
        return pa, pb, w, th, q / r

    def phase_back_emf_v(self, theta_e_rad: float, omega_m_rad_s: float
                         ) -> tuple[float, float, float]:
        """Phase back-EMFs (e_a, e_b, e_c), V: the rate of change of the magnet's flux linkage
        with each phase, e_x = -omega_e psi_m sin(theta_e - n_x 120 deg), omega_e = p omega_m,
        n_a, n_b, n_c = 0, 1, 2 (so v_x - v_star = R i_x + L di_x/dt + e_x). Sinusoidal."""
        amplitude = -self.p * omega_m_rad_s * self.psim
        third = 2.0 * math.pi / 3.0
        return (amplitude * sin(theta_e_rad), amplitude * sin(theta_e_rad - third),
                amplitude * sin(theta_e_rad + third))


def rk4_spm_step(p: float, ril: float, rk: float, kti: float, ij: float, bw: float, va: float,
                 vb: float, h: float, tl1: float, tl2: float, tl4: float, pa: float, pb: float,
                 w: float, th: float) -> tuple[float, float, float, float]:
    """One classic RK4 step of length h of the Ld = Lq = L motor at the constant stator voltage
    (va, vb), with the load torque at the step's start, middle and end (tl1, tl2, tl4):
    ril = R/L, rk = R psi_m/L, kti = 1.5 p psi_m/L, ij = 1/J, bw the speed-proportional torque.
    Returns (psi_alpha, psi_beta, w, theta_m). MotorModel.advance and advance_pieces both take
    it (each with its own load-time bookkeeping); plant_rt/c/_plantnet.c's rk4_spm_step is the
    same operations in the same order.

    Ld = Lq = L: i = (psi - psi_m e_d)/L, so u - R i = u - (R/L) psi + (R psi_m/L) e_d and the
    psi_m terms cancel out of eq. (6): T = 1.5 p psi_m/L (c psi_b - s psi_a).
    """
    h2 = 0.5 * h
    h6 = h / 6.0
    e = p * th
    c = cos(e)
    s = sin(e)
    d1a = va - ril * pa + rk * c
    d1b = vb - ril * pb + rk * s
    d1w = (kti * (c * pb - s * pa) - bw * w - tl1) * ij
    xa = pa + h2 * d1a
    xb = pb + h2 * d1b
    w2 = w + h2 * d1w
    e = p * (th + h2 * w)
    c = cos(e)
    s = sin(e)
    d2a = va - ril * xa + rk * c
    d2b = vb - ril * xb + rk * s
    d2w = (kti * (c * xb - s * xa) - bw * w2 - tl2) * ij
    xa = pa + h2 * d2a
    xb = pb + h2 * d2b
    w3 = w + h2 * d2w
    e = p * (th + h2 * w2)
    c = cos(e)
    s = sin(e)
    d3a = va - ril * xa + rk * c
    d3b = vb - ril * xb + rk * s
    d3w = (kti * (c * xb - s * xa) - bw * w3 - tl2) * ij
    xa = pa + h * d3a
    xb = pb + h * d3b
    w4 = w + h * d3w
    e = p * (th + h * w3)
    c = cos(e)
    s = sin(e)
    d4a = va - ril * xa + rk * c
    d4b = vb - ril * xb + rk * s
    d4w = (kti * (c * xb - s * xa) - bw * w4 - tl4) * ij
    return (pa + h6 * (d1a + 2.0 * (d2a + d3a) + d4a),
            pb + h6 * (d1b + 2.0 * (d2b + d3b) + d4b),
            w + h6 * (d1w + 2.0 * (d2w + d3w) + d4w),
            th + h6 * (w + 2.0 * (w2 + w3) + w4))
