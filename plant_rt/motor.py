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

Back-EMF shape (``back_emf``): the magnet's flux linkage with phase x (n_a, n_b, n_c = 0, 1, 2)
is psi_r g(theta_e - n_x 2pi/3). ``sinusoidal`` (default): g = cos, everything above.
``trapezoidal`` (surface magnets only, Ld = Lq = L): g' is a trapezoid of peak 1 with the
zeros of -sin and a flat top of back_emf_flat_top_deg (trapezoid_shape), so the phase back-EMF
e_x = omega_e psi_r g'(theta_e - n_x 2pi/3). The star point floats (i_a + i_b + i_c = 0), so
only the magnet flux's non-zero-sequence part acts, its Clarke transform psi_m,ab(theta_e)
(magnet_flux_ab); then

    i_ab = (psi_ab - psi_m,ab(theta_e)) / L
    T = p sum_x psi_r g'(theta_e - n_x 2pi/3) i_x = 1.5 p (psi_m,ab'(theta_e) . i_ab)

and eq. (1) is unchanged. This machine runs in Python only (the C kernel is sinusoidal).
"""
from __future__ import annotations

from configfile.dataclass_methods import dataclass
import math
from math import cos, pi, sin

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
    back_emf: str = param("sinusoidal", choices=("sinusoidal", "trapezoidal"))
    back_emf_flat_top_deg: float = param(120.0, gt=0, lt=180)

    def problems(self) -> list[tuple[str, str]]:
        """(key, message) for combinations the model cannot simulate."""
        if self.back_emf == "trapezoidal" and self.inductance_d_h != self.inductance_q_h:
            return [("inductance_q_h",
                     f"back_emf trapezoidal needs surface magnets: inductance_d_h "
                     f"({self.inductance_d_h:g}) must equal inductance_q_h "
                     f"({self.inductance_q_h:g})")]
        return []


HALF_PI = 0.5 * pi
TWO_PI = 2.0 * pi
THIRD_TURN = TWO_PI / 3.0
INV_SQRT3 = 1.0 / math.sqrt(3.0)


def trapezoid_shape(theta_e: float, ramp_rad: float) -> tuple[float, float]:
    """(g(theta_e), g'(theta_e)) of the trapezoidal machine's unit flux linkage g.

    g' is the back-EMF per (omega_e psi_r): 0 at theta_e = 0 and pi (the zeros of -sin),
    -1 on the flat top [ramp, pi - ramp] (ramp = (pi - flat top)/2), linear in between,
    g'(theta + pi) = -g'(theta). g is its integral with no mean:
        g(u) = pi/2 - ramp/2 - u^2/(2 ramp)   0 <= u <= ramp
        g(u) = pi/2 - u                       ramp <= u <= pi/2
    g(pi - u) = -g(u), g(-u) = g(u), g(u + pi) = -g(u). Exact piecewise closed form: the
    trapezoid's Fourier series (4/(pi n^2 ramp)) sin(n ramp) converges as 1/n^2 (measured at
    a 120 deg flat top: 1.6e-5 of the peak EMF with 1e4 harmonics, 1e-6 takes ~5e4; the flux
    ~400), where this costs one reduction and a branch.
    """
    u = theta_e % TWO_PI
    sign = 1.0
    if u >= pi:
        u -= pi
        sign = -1.0
    g_sign = sign
    if u > HALF_PI:
        u = pi - u
        g_sign = -sign
    if u < ramp_rad:
        return g_sign * (HALF_PI - 0.5 * ramp_rad - 0.5 * u * u / ramp_rad), -sign * u / ramp_rad
    return g_sign * (HALF_PI - u), -sign


class MotorModel:
    """Derived constants and the stator/rotor maths on plain floats (no numpy: hot path)."""

    __slots__ = ("params", "p", "r", "psim", "ld", "lq", "ild", "ilq", "j", "ij", "b", "kt", "spm",
                 "_k", "trapezoidal", "ramp_rad")

    def __init__(self, params: MotorParams):
        self.set_params(params)

    def set_params(self, params: MotorParams) -> None:
        for key, message in params.problems():
            raise ValueError(f"motor {key}: {message}")
        self.params = params
        #: the trapezoidal back-EMF machine (Python only: the C kernel is sinusoidal)
        self.trapezoidal = params.back_emf == "trapezoidal"
        self.ramp_rad = 0.5 * (pi - math.radians(params.back_emf_flat_top_deg))
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
        if self.trapezoidal:
            ma, mb, _, _ = self.magnet_flux_ab(e)
            ia = (pa - ma) * self.ild
            ib = (pb - mb) * self.ild
            return ia, ib, c * ia + s * ib, c * ib - s * ia
        i_d = (c * pa + s * pb - self.psim) * self.ild
        i_q = (c * pb - s * pa) * self.ilq
        return c * i_d - s * i_q, s * i_d + c * i_q, i_d, i_q

    def flux_from_currents(self, i_d: float, i_q: float, theta_m: float) -> tuple[float, float]:
        """Stationary-frame flux linkage of the given rotor-frame currents."""
        e = self.p * theta_m
        c, s = cos(e), sin(e)
        if self.trapezoidal:
            ma, mb, _, _ = self.magnet_flux_ab(e)
            return ma + self.ld * (c * i_d - s * i_q), mb + self.ld * (s * i_d + c * i_q)
        pd = self.ld * i_d + self.psim
        pq = self.lq * i_q
        return c * pd - s * pq, s * pd + c * pq

    def torque(self, i_d: float, i_q: float) -> float:
        """1.5 p (psi_m i_q + (Ld - Lq) i_d i_q): the rotor-frame form of eq. (6)."""
        return self.kt * (self.psim * i_q + (self.ld - self.lq) * i_d * i_q)

    def torque_ab(self, i_alpha: float, i_beta: float, theta_m: float) -> float:
        """Torque of stationary-frame currents at the rotor angle, either shape:
        T = p sum_x psi_r g'(theta_e - n_x 2pi/3) i_x = 1.5 p psi_m,ab'(theta_e) . i_ab
        (sum_x e_x i_x / omega_m with no division: finite at standstill)."""
        e = self.p * theta_m
        if self.trapezoidal:
            _, _, da, db = self.magnet_flux_ab(e)
            return self.kt * (da * i_alpha + db * i_beta)
        c, s = cos(e), sin(e)
        return self.torque(c * i_alpha + s * i_beta, c * i_beta - s * i_alpha)

    def magnet_flux_ab(self, theta_e: float) -> tuple[float, float, float, float]:
        """The trapezoidal machine's magnet flux linkage in the stationary frame and its
        derivative by theta_e: (psi_m,alpha, psi_m,beta, dpsi_m,alpha, dpsi_m,beta), the
        amplitude-invariant Clarke transform of psi_r g(theta_e - n_x 2pi/3), x = a, b, c
        (it drops the zero-sequence part, which a floating star point cannot drive):
            psi_m,alpha = 2/3 psi_r (g_a - (g_b + g_c)/2),  psi_m,beta = psi_r (g_b - g_c)/sqrt3
        """
        ramp = self.ramp_rad
        ga, fa = trapezoid_shape(theta_e, ramp)
        gb, fb = trapezoid_shape(theta_e - THIRD_TURN, ramp)
        gc, fc = trapezoid_shape(theta_e + THIRD_TURN, ramp)
        k = self.psim
        k23 = k * (2.0 / 3.0)
        ks = k * INV_SQRT3
        return (k23 * (ga - 0.5 * (gb + gc)), ks * (gb - gc),
                k23 * (fa - 0.5 * (fb + fc)), ks * (fb - fc))

    def derivatives(self, pa: float, pb: float, w: float, th: float, va: float, vb: float,
                    tl: float, bw: float) -> tuple[float, float, float]:
        """Trapezoidal machine: (dpsi_alpha/dt, dpsi_beta/dt, dw/dt) at stator voltage (va, vb)
        and load torque tl + bw w:
            dpsi_ab/dt = u_ab - R (psi_ab - psi_m,ab(theta_e))/L
            J dw/dt = 1.5 p psi_m,ab'(theta_e) . i_ab - bw w - tl        (d theta_m/dt = w)
        """
        ma, mb, da, db = self.magnet_flux_ab(self.p * th)
        ild = self.ild
        ia = (pa - ma) * ild
        ib = (pb - mb) * ild
        r = self.r
        return (va - r * ia, vb - r * ib,
                (self.kt * (da * ia + db * ib) - bw * w - tl) * self.ij)

    def _advance_shaped(self, pa: float, pb: float, w: float, th: float, va: float, vb: float,
                        h: float, n: int, tl0: float, tl_slope: float, bw: float
                        ) -> tuple[float, float, float, float]:
        """advance() for the trapezoidal machine: n steps of length h, each of them cut where
        the rotor passes a corner of the trapezoid (corner_times), every piece one classic RK4
        step on derivatives(). At a corner d e/dt jumps, and an RK4 step across it would lose
        its order (measured against solve_ivp, 50 ms of six-step at 50 us: 9e-6 of the peak
        current without the cut, 7e-9 with it, near the sinusoid's 2e-9)."""
        t = 0.0
        for _ in range(n):
            a = 0.0
            for b in self.corner_times(th, w, h):
                pa, pb, w, th = self._rk4_shaped(pa, pb, w, th, va, vb, b - a,
                                                 tl0 + tl_slope * (t + a), tl_slope, bw)
                a = b
            pa, pb, w, th = self._rk4_shaped(pa, pb, w, th, va, vb, h - a,
                                             tl0 + tl_slope * (t + a), tl_slope, bw)
            t += h
        return pa, pb, w, th

    def corner_times(self, th: float, w: float, h: float) -> list[float]:
        """Times in (0, h) at which the rotor, turning at w from th, reaches a corner of the
        trapezoidal back-EMF: theta_e = +-ramp (mod 60 deg) for the three phases together.
        The speed is taken constant over the step: a corner missed by the acceleration's
        O(h^2) angle leaves a local error of the cube of that, far below RK4's own."""
        we = self.p * w
        if we == 0.0:
            return []
        sector = pi / 3.0
        phi = (self.p * th) % sector
        out = []
        for corner in (self.ramp_rad % sector, -self.ramp_rad % sector):
            d = (corner - phi) % sector if we > 0.0 else (phi - corner) % sector
            tc = d / abs(we)
            step = sector / abs(we)
            while tc < h:
                if 1e-9 * h < tc < h * (1.0 - 1e-9):
                    out.append(tc)
                tc += step
        out.sort()
        return out

    def _rk4_shaped(self, pa: float, pb: float, w: float, th: float, va: float, vb: float,
                    h: float, tl1: float, tl_slope: float, bw: float
                    ) -> tuple[float, float, float, float]:
        """One classic RK4 step of the trapezoidal machine (load tl1 + tl_slope t)."""
        f = self.derivatives
        h2 = 0.5 * h
        h6 = h / 6.0
        tl2 = tl1 + tl_slope * h2
        tl4 = tl1 + tl_slope * h
        d1a, d1b, d1w = f(pa, pb, w, th, va, vb, tl1, bw)
        w2 = w + h2 * d1w
        d2a, d2b, d2w = f(pa + h2 * d1a, pb + h2 * d1b, w2, th + h2 * w, va, vb, tl2, bw)
        w3 = w + h2 * d2w
        d3a, d3b, d3w = f(pa + h2 * d2a, pb + h2 * d2b, w3, th + h2 * w2, va, vb, tl2, bw)
        w4 = w + h * d3w
        d4a, d4b, d4w = f(pa + h * d3a, pb + h * d3b, w4, th + h * w3, va, vb, tl4, bw)
        return (pa + h6 * (d1a + 2.0 * (d2a + d3a) + d4a),
                pb + h6 * (d1b + 2.0 * (d2b + d3b) + d4b),
                w + h6 * (d1w + 2.0 * (d2w + d3w) + d4w),
                th + h6 * (w + 2.0 * (w2 + w3) + w4))

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
        if self.trapezoidal:
            return self._advance_shaped(pa, pb, w, th, va, vb, h, n, tl0, tl_slope, bw)
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
        spm = self.spm and not self.trapezoidal     # advance() takes the trapezoidal machine
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
        """(e_a, e_b, e_c), the back-EMF of each phase (V) at electrical angle theta_e_rad and
        mechanical speed omega_m_rad_s: e_x = omega_e psi_r g'(theta_e - n_x 2pi/3) with
        omega_e = p omega_m; sinusoidal g' = -sin, trapezoidal the trapezoid of trapezoid_shape
        (same zeros, peak omega_e psi_r, flat top back_emf_flat_top_deg)."""
        k = self.p * omega_m_rad_s * self.psim
        if self.trapezoidal:
            ramp = self.ramp_rad
            return (k * trapezoid_shape(theta_e_rad, ramp)[1],
                    k * trapezoid_shape(theta_e_rad - THIRD_TURN, ramp)[1],
                    k * trapezoid_shape(theta_e_rad + THIRD_TURN, ramp)[1])
        return (-k * sin(theta_e_rad), -k * sin(theta_e_rad - THIRD_TURN),
                -k * sin(theta_e_rad + THIRD_TURN))


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
