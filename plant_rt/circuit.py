"""The general electrical network of one interval: inverter legs (driven or through their
diodes), DC link, stator and rotor, integrated by RK4 with event location.

Used whenever the plant's fast path does not apply (an open leg, a device voltage drop, a
resistive or capacitive DC link, a locked rotor). Each phase x is in one of five states:

    H, L   leg driven: terminal at v_dc - drop(i_x) or -drop(i_x)
    P, N   leg open, current through the low (i_x > 0) or high (i_x < 0) diode:
           terminal at -U_d or v_dc + U_d
    O      leg open, no current: the terminal floats

with drop(i) = U_d clamp(i / i_knee, -1, 1) (a device conducting like a resistor below the
knee current; U_d = device_drop_v). Star point floating, so sum i_x = 0:

  * no phase in O: u_ab = 2/3 sum V_x e_x (Clarke of the terminal voltages, eq. (7)).
  * one phase x in O: its terminal voltage V_x is the value that keeps d i_x/dt = 0 (one
    linear equation, valid for Ld != Lq), and i_x is projected back to 0 after each step.
  * two or more in O: no current can flow; the stator flux is the magnet's and u is the
    back-EMF.

Events end a step early, located by re-integrating from the step's start (Illinois method):
a P/N current reaching zero (the phase becomes O), a floating terminal of an O phase leaving
[-U_d, v_dc + U_d] (the diode it reaches turns on), with no current at all a line back-EMF
overcoming the rails (the pair of diodes or switches that conducts first turns on), and, with
a device drop, a driven leg's current crossing +-i_knee: the drop's kink, where the RHS is
continuous but not smooth, so an RK4 step across it would lose its order (1e-4 of the peak
against the switched-circuit reference before; the step now ends there, nothing changes state).
This is what makes the safe state at 3000 rpm decay to zero and then stay there while the line
back-EMF is below the 70 V link.
With a trapezoidal back-EMF (plant_rt.motor) the trapezoid's corners, where d e/dt jumps, end
a step in the same way as a knee (the rhs is then _rhs_shaped).

The load torque within an interval is the linear piece set by set_load_segment (the plant cuts
its intervals at the profile's knots), plus the speed term.

C kernel: with plant_rt.ckernel's extension built (and HIL_PLANT_PURE_PYTHON unset), integrate()
and begin()'s settling run in C (plant_rt/c/_plantnet.c, the same operations in the same order),
one call per interval; this Python code is the reference and the fallback (``ckernel = None``).
After a C call only the phase states, the counters and ``vdc`` are updated (the per-evaluation
values ``cur``, ``te``, ``vx`` are the Python path's).

An open phase (a broken wire or connector between leg x and the motor, a fault) keeps phase x
in O whatever its leg does: its terminal floats with no diode to catch it, so it has no turn-on
event and takes no part in a release pair; the other two phases carry opposite currents.
"""
from __future__ import annotations

import math
from math import cos, sin

from plant_rt import ckernel
from plant_rt.dc_link import DcLink
from plant_rt.inverter import H, L, N, O, P, PHASE_AXES, SQRT3, InverterParams
from plant_rt.load import Load
from plant_rt.motor import MotorModel

S32 = 0.5 * SQRT3
INV_SQRT3 = 1.0 / SQRT3
TWO_THIRDS = 2.0 / 3.0
#: Currents smaller than this (A) in a leg that opens are taken as zero (numerical noise).
ZERO_CURRENT_A = 1e-9
MAX_EVENTS_PER_INTERVAL = 64


def _dc_current(kinds: list[int], cur: tuple) -> float:
    """The DC-link current: the phase currents of the legs tied to DC+ (high switch or high
    diode)."""
    idc = 0.0
    for x in range(3):
        if kinds[x] == H or kinds[x] == N:
            idc += cur[x]
    return idc


class Network:
    """Leg states that persist across intervals, the general RHS and the event-aware RK4."""

    def __init__(self, motor: MotorModel, inverter: InverterParams, dc: DcLink, load: Load):
        self.motor = motor
        self.dc = dc
        self.load = load
        self.set_inverter(inverter)
        self.kinds: list[int] = [O, O, O]
        self.zero: list[int] = [0, 1, 2]
        self.all_zero = True
        self.event_overflows = 0
        self.events = 0
        # Values of the last rhs() call, for events and outputs.
        self.cur = (0.0, 0.0, 0.0)
        self.vx = 0.0
        self.vdc = dc.source_v
        self.g_release = -1.0
        self._emf = (0.0, 0.0)
        self._legs: tuple[int, int, int] | None = None
        self.release_pair = (0, 1)
        self.te = 0.0
        self.open_phase: int | None = None
        # per phase: +1 while |i| > i_knee at the last accepted state, -1 inside the knee
        # (which way the knee event looks); only with a device drop
        self._knee_side = [0, 0, 0]
        # trapezoidal machine: the sign of each corner family's wave at the last accepted state
        self._corner_side = [1.0, 1.0]
        self._theta_e = 0.0
        # load profile over the interval: value v0 at t_a, slope (set_load_segment)
        self._tl = (0.0, 0.0, 0.0)
        #: the C kernel (plant_rt.ckernel.KERNEL), None for this Python implementation
        self.ckernel = ckernel.KERNEL

    def set_load_segment(self, t_a: float, v0: float, slope: float) -> None:
        """The load profile is v0 + slope (t - t_a) over the coming interval (no knot in it)."""
        self._tl = (t_a, v0, slope)

    def legs_code(self) -> int:
        """The legs of the last begin() for the C kernel: l0 + 5 l1 + 25 l2, -1 for none."""
        legs = self._legs
        return -1 if legs is None else legs[0] + 5 * legs[1] + 25 * legs[2]

    def set_state(self, kinds, legs_code: int, events: int, overflows: int) -> None:
        """The state a C kernel call left: phase states, last legs (legs_code), counts."""
        self._configure(list(kinds))
        self._legs = None if legs_code < 0 else (legs_code % 5, legs_code // 5 % 5, legs_code // 25)
        self.events += events
        self.event_overflows += overflows

    def _cfg(self) -> tuple:
        """The parameters the C kernel takes besides the motor's constants, in the order of its
        cfg_t (plant_rt/c/_plantnet.c): dc_link_mode (0 ideal, 1 resistive, 2 dynamic),
        dc_source_v, dc_source_resistance_ohm, inv_dc_capacitance_per_f,
        dc_source_unidirectional, device_drop_v, device_knee_a, load_locked,
        load_nm_per_rad_s, load_t0_s, load_torque0_nm, load_slope_nm_per_s, open_phase
        (-1: none)."""
        dc, load = self.dc, self.load
        t_a, v0, slope = self._tl
        return (2.0 if dc.dynamic else 1.0 if dc.resistive else 0.0, dc.source_v, dc.rs, dc.ic,
                1.0 if dc.unidirectional else 0.0, self.ud, self.knee,
                1.0 if load.locked else 0.0, load.kw, t_a, v0, slope,
                -1.0 if self.open_phase is None else float(self.open_phase))

    def set_open_phase(self, phase: int | None) -> None:
        """Phase 0, 1 or 2 disconnected from its leg (None: all connected)."""
        self.open_phase = phase
        self._legs = None

    def set_inverter(self, inverter: InverterParams) -> None:
        self.ud = inverter.device_drop_v
        self.knee = inverter.device_knee_a

    # ------------------------------------------------------------ leg states
    def _configure(self, kinds: list[int]) -> None:
        zero = [x for x in range(3) if kinds[x] == O]
        if len(zero) >= 2:
            # Two phases without current leave none for the third (star point): an open leg
            # whose diode was still marked conducting carries nothing either.
            kinds = [O if k in (P, N) else k for k in kinds]
            zero = [x for x in range(3) if kinds[x] == O]
        self.kinds = kinds
        self.zero = zero
        self.all_zero = len(zero) >= 2

    def begin(self, t: float, y: list[float], legs: tuple[int, int, int]) -> None:
        """Sets the phase states for an interval with the given leg states (H, L or O=open)."""
        if legs == self._legs:
            return      # continuing: the last step's event check already holds for this state
        self._legs = legs
        ia, ib, _, _ = self.motor.currents(y[0], y[1], y[3])
        cur = (ia, -0.5 * ia + S32 * ib, -0.5 * ia - S32 * ib)
        kinds = []
        cut = self.open_phase
        for x in range(3):
            if x == cut:
                kinds.append(O)
            elif legs[x] != O:
                kinds.append(legs[x])
            elif self.kinds[x] in (P, N, O):
                kinds.append(self.kinds[x])        # still open: its diode state carries on
            elif cur[x] > ZERO_CURRENT_A:
                kinds.append(P)
            elif cur[x] < -ZERO_CURRENT_A:
                kinds.append(N)
            else:
                kinds.append(O)
        self._configure(kinds)
        if self.zero:                   # only a floating phase can start to conduct
            if self.ckernel is not None:
                y[:], kinds, events = self.ckernel.settle(self.motor._k, self._cfg(), self.kinds,
                                                          t, y)
                self._configure(list(kinds))
                self.events += events
                return
            self._project(y)
            self._settle(t, y)

    def invalidate(self) -> None:
        """Something outside changed (a parameter, the source voltage): re-check next time."""
        self._legs = None

    def set_driven(self, legs: tuple[int, int, int]) -> None:
        """The fast path ran an all-driven interval: remember it for the next open leg."""
        if self.open_phase is not None:
            self._configure([O if x == self.open_phase else legs[x] for x in range(3)])
        else:
            self.kinds = list(legs)
            self.zero = []
            self.all_zero = False
        self._legs = None

    def _project(self, y: list[float]) -> None:
        """Puts the state back on the constraint of the current O phases."""
        m = self.motor
        if not self.zero:
            return
        e = m.p * y[3]
        c, s = cos(e), sin(e)
        if self.all_zero:
            if m.trapezoidal:
                y[0], y[1], _, _ = m.magnet_flux_ab(e)
                return
            y[0] = m.psim * c
            y[1] = m.psim * s
            return
        self.project_phase(self.zero[0], y)

    def project_phase(self, x: int, y: list[float]) -> None:
        """Moves the flux along phase x's axis until i_x = 0 (the other currents keep their
        difference)."""
        m = self.motor
        e = m.p * y[3]
        c, s = cos(e), sin(e)
        ex0, ex1 = PHASE_AXES[x]
        ia, ib, _, _ = m.currents(y[0], y[1], y[3])
        ix = ex0 * ia + ex1 * ib
        rd = c * ex0 + s * ex1
        rq = c * ex1 - s * ex0
        delta = -ix / (rd * rd * m.ild + rq * rq * m.ilq)
        y[0] += delta * ex0
        y[1] += delta * ex1

    def _settle(self, t: float, y: list[float]) -> None:
        """Applies every turn-on condition that holds now (an O phase whose diode conducts)."""
        for _ in range(6):
            self.rhs(t, y[0], y[1], y[2], y[3], y[4])
            best = None
            self._note_knee_sides()
            for g, tag in self.event_values():
                if tag[0] not in ("i", "k") and g > 0.0 and (best is None or g > best[0]):
                    best = (g, tag)
            if best is None:
                return
            self._transition(t, best[1], y)

    def _transition(self, t: float, tag: tuple, y: list[float]) -> None:
        if tag[0] == "k":               # a knee: the step stopped at the kink, no state changes
            self.events += 1
            return
        kinds = list(self.kinds)
        if tag[0] == "i":
            kinds[tag[1]] = O
        elif tag[0] == "hi":
            kinds[tag[1]] = N
        elif tag[0] == "lo":
            kinds[tag[1]] = P
        else:
            self.rhs(t, y[0], y[1], y[2], y[3], y[4])      # the pair at this very state
            self.event_values()
            out, into = self.release_pair
            if kinds[out] == O:
                kinds[out] = N
            if kinds[into] == O:
                kinds[into] = P
        self._configure(kinds)
        self._project(y)
        self.events += 1

    # ------------------------------------------------------------------- RHS
    def rhs(self, t: float, pa: float, pb: float, w: float, th: float, v: float
            ) -> tuple[float, float, float, float, float, float, float, float]:
        """(dpsi_a, dpsi_b, dw, dtheta, dv_dc, u_alpha, u_beta, i_dc) at time t (s, absolute)."""
        m = self.motor
        if m.trapezoidal:
            return self._rhs_shaped(t, pa, pb, w, th, v)
        p, r, psim, ild, ilq = m.p, m.r, m.psim, m.ild, m.ilq
        e = p * th
        c = cos(e)
        s = sin(e)
        we = p * w
        dc = self.dc
        if self.all_zero:
            va = -we * psim * s
            vb = we * psim * c
            dpa, dpb, te, idc = va, vb, 0.0, 0.0
            vdc = dc.voltage(v, 0.0)
            self.cur = (0.0, 0.0, 0.0)
            self._emf = (va, vb)
        else:
            pd = c * pa + s * pb
            pq = c * pb - s * pa
            i_d = (pd - psim) * ild
            i_q = pq * ilq
            ia = c * i_d - s * i_q
            ib = s * i_d + c * i_q
            cur = (ia, -0.5 * ia + S32 * ib, -0.5 * ia - S32 * ib)
            kinds = self.kinds
            idc = _dc_current(kinds, cur)
            vdc = dc.voltage(v, idc)
            va, vb = self._terminal_ab(kinds, cur, vdc)
            if self.zero:
                ex0, ex1 = PHASE_AXES[self.zero[0]]
                did = (c * va + s * vb - r * i_d + we * pq) * ild
                diq = (c * vb - s * va - r * i_q - we * pd) * ilq
                rd = c * ex0 + s * ex1
                rq = c * ex1 - s * ex0
                g0 = rd * did + rq * diq + we * (ex1 * ia - ex0 * ib)
                vx = -g0 / (TWO_THIRDS * (rd * rd * ild + rq * rq * ilq))
                va += TWO_THIRDS * ex0 * vx
                vb += TWO_THIRDS * ex1 * vx
                self.vx = vx
            dpa = va - r * ia
            dpb = vb - r * ib
            te = m.kt * (pd * i_q - pq * i_d)
            self.cur = cur
        self.vdc = vdc
        self.te = te
        return dpa, dpb, self._speed_rate(t, w, te), w, dc.dv_dt(v, idc), va, vb, idc

    def _rhs_shaped(self, t: float, pa: float, pb: float, w: float, th: float, v: float
                    ) -> tuple[float, float, float, float, float, float, float, float]:
        """rhs() of the trapezoidal machine (Ld = Lq = L; plant_rt.motor's magnet_flux_ab):
        i_ab = (psi_ab - psi_m,ab)/L, back-EMF e_ab = omega_e psi_m,ab', torque
        1.5 p psi_m,ab' . i_ab. A floating phase x keeps d i_x/dt = 0:
        x . (u_ab + 2/3 x V_x - R i_ab - e_ab) = 0 with |x| = 1 gives V_x."""
        m = self.motor
        r, ild = m.r, m.ild
        self._theta_e = m.p * th
        ma, mb, da, db = m.magnet_flux_ab(self._theta_e)
        we = m.p * w
        dc = self.dc
        if self.all_zero:
            va = we * da
            vb = we * db
            dpa, dpb, te, idc = va, vb, 0.0, 0.0
            vdc = dc.voltage(v, 0.0)
            self.cur = (0.0, 0.0, 0.0)
            self._emf = (va, vb)
        else:
            ia = (pa - ma) * ild
            ib = (pb - mb) * ild
            cur = (ia, -0.5 * ia + S32 * ib, -0.5 * ia - S32 * ib)
            kinds = self.kinds
            idc = _dc_current(kinds, cur)
            vdc = dc.voltage(v, idc)
            va, vb = self._terminal_ab(kinds, cur, vdc)
            if self.zero:
                ex0, ex1 = PHASE_AXES[self.zero[0]]
                vx = -(ex0 * (va - r * ia - we * da) + ex1 * (vb - r * ib - we * db)) / TWO_THIRDS
                va += TWO_THIRDS * ex0 * vx
                vb += TWO_THIRDS * ex1 * vx
                self.vx = vx
            dpa = va - r * ia
            dpb = vb - r * ib
            te = m.kt * (da * ia + db * ib)
            self.cur = cur
        self.vdc = vdc
        self.te = te
        return dpa, dpb, self._speed_rate(t, w, te), w, dc.dv_dt(v, idc), va, vb, idc

    def _speed_rate(self, t: float, w: float, te: float) -> float:
        """dw/dt from the torque te at time t: J dw/dt = te - b w - (load profile + kw w); 0 with
        the rotor locked."""
        if self.load.locked:
            return 0.0
        m = self.motor
        t_a, v0, slope = self._tl
        return (te - m.b * w - ((v0 + slope * (t - t_a)) + self.load.kw * w)) * m.ij

    def _terminal_ab(self, kinds: list[int], cur: tuple, vdc: float) -> tuple[float, float]:
        """u_ab of the driven and diode-conducting terminals (eq. (7); an O phase adds 0)."""
        ud = self.ud
        vt = [0.0, 0.0, 0.0]
        for x in range(3):
            k = kinds[x]
            if k == H or k == L:
                drop = 0.0
                if ud:
                    z = cur[x] / self.knee
                    drop = ud * (1.0 if z > 1.0 else -1.0 if z < -1.0 else z)
                vt[x] = (vdc if k == H else 0.0) - drop
            elif k == P:
                vt[x] = -ud
            elif k == N:
                vt[x] = vdc + ud
        return (2.0 * vt[0] - vt[1] - vt[2]) / 3.0, (vt[1] - vt[2]) * INV_SQRT3

    def _release(self, va: float, vb: float, vdc: float) -> None:
        """With no current anywhere: how far the first pair of legs is from conducting.

        Current would leave the motor at x (through x's high diode, or its switch) and enter
        at y when e_x - A_x > e_y - B_y: A_x = v_dc + U_d for an open leg (v_dc driven high,
        0 driven low), B_y = -U_d for an open leg (v_dc, 0 when driven).
        """
        ud = self.ud
        kinds = self.kinds
        up = []
        lo = []
        for x in range(3):
            ex = PHASE_AXES[x][0] * va + PHASE_AXES[x][1] * vb
            k = kinds[x]
            if k == O:
                up.append(ex - vdc - ud)
                lo.append(ex + ud)
            else:
                rail = vdc if k == H else 0.0
                up.append(ex - rail)
                lo.append(ex - rail)
        best = -math.inf
        pair = (0, 1)
        cut = self.open_phase
        for x, y in ((0, 1), (0, 2), (1, 0), (1, 2), (2, 0), (2, 1)):
            if x == cut or y == cut:
                continue
            g = up[x] - lo[y]
            if g > best:
                best, pair = g, (x, y)
        self.g_release = best
        self.release_pair = pair

    def event_values(self) -> list[tuple[float, tuple]]:
        """Event functions at the last rhs() state; an event fires when one becomes > 0."""
        out = []
        kinds, cur = self.kinds, self.cur
        if self.all_zero:
            self._release(self._emf[0], self._emf[1], self.vdc)
            out.append((self.g_release, ("rel",)))
            return out
        for x in range(3):
            if kinds[x] == P:
                out.append((-cur[x], ("i", x)))
            elif kinds[x] == N:
                out.append((cur[x], ("i", x)))
        if self.zero and self.zero[0] != self.open_phase:
            x = self.zero[0]
            out.append((self.vx - self.vdc - self.ud, ("hi", x)))
            out.append((-self.ud - self.vx, ("lo", x)))
        if self.ud:
            knee, side = self.knee, self._knee_side
            for x in range(3):
                if (kinds[x] == H or kinds[x] == L) and side[x]:
                    out.append((side[x] * (knee - abs(cur[x])), ("k", x)))
        if self.motor.trapezoidal:
            # the trapezoid's corners (theta_e = +-ramp mod 60 deg), where d e/dt jumps: a
            # step ends there as at a knee, so that RK4 keeps its order
            for k, side in enumerate(self._corner_side):
                out.append((-side * self._corner_wave(k), ("k", -1)))
        return out

    def _corner_wave(self, k: int) -> float:
        """sin(3 (theta_e -+ ramp)) at the last rhs() state: zero at every corner of family k."""
        ramp = self.motor.ramp_rad
        return sin(3.0 * (self._theta_e - ramp if k == 0 else self._theta_e + ramp))

    def _note_knee_sides(self) -> None:
        """Which side of the knee each driven current is on at the last rhs() state."""
        if self.ud:
            knee, cur = self.knee, self.cur
            self._knee_side = [1 if abs(cur[x]) > knee else -1 for x in range(3)]
        if self.motor.trapezoidal:
            self._corner_side = [1.0 if self._corner_wave(k) > 0.0 else -1.0 for k in (0, 1)]

    # ----------------------------------------------------------- integration
    def _rk4(self, t: float, y: list[float], h: float, k1: tuple) -> tuple[list[float], tuple]:
        rhs = self.rhs
        h2 = 0.5 * h
        pa, pb, w, th, v = y
        k2 = rhs(t + h2, pa + h2 * k1[0], pb + h2 * k1[1], w + h2 * k1[2], th + h2 * k1[3],
                 v + h2 * k1[4])
        k3 = rhs(t + h2, pa + h2 * k2[0], pb + h2 * k2[1], w + h2 * k2[2], th + h2 * k2[3],
                 v + h2 * k2[4])
        k4 = rhs(t + h, pa + h * k3[0], pb + h * k3[1], w + h * k3[2], th + h * k3[3],
                 v + h * k3[4])
        h6 = h / 6.0
        out = [y[i] + h6 * (k1[i] + 2.0 * (k2[i] + k3[i]) + k4[i]) for i in range(5)]
        quad = tuple(h6 * (k1[i] + 2.0 * (k2[i] + k3[i]) + k4[i]) for i in (5, 6, 7))
        if self.load.locked:
            out[2] = 0.0
        return out, quad

    def _state_after(self, t: float, y: list[float], h: float, k1: tuple
                     ) -> tuple[list[float], tuple, list[tuple[float, tuple]]]:
        y1, quad = self._rk4(t, y, h, k1)
        self.rhs(t + h, *y1)
        return y1, quad, self.event_values()

    def integrate(self, t0: float, t1: float, y: list[float], h_max: float,
                  acc: list[float]) -> list[float]:
        """Integrates [t0, t1] (absolute s) from y; adds int u_alpha, u_beta, i_dc dt to acc."""
        if self.ckernel is not None:
            y, kinds, events, overflows, self.vdc = self.ckernel.integrate(
                self.motor._k, self._cfg(), self.kinds, t0, t1, y, h_max, acc)
            self._configure(list(kinds))
            self.events += events
            self.event_overflows += overflows
            return y
        n = max(1, math.ceil((t1 - t0) / h_max - 1e-9))
        if self.all_zero:
            coasted = self._coast(t0, t1, y, n, acc)
            if coasted is not None:
                return coasted
        h_nom = (t1 - t0) / n
        t = t0
        budget = MAX_EVENTS_PER_INTERVAL
        k1 = self.rhs(t, *y)
        self._note_knee_sides()
        g0 = self.event_values()
        while t1 - t > 1e-12 * h_nom:
            h = min(h_nom, t1 - t)
            if t + h > t1 - 1e-9 * h_nom:
                h = t1 - t
            y1, quad, g1 = self._state_after(t, y, h, k1)
            fired = []
            if budget > 0 and len(g1) == len(g0):
                for j, ((a, tag), (b, _)) in enumerate(zip(g0, g1)):
                    if b > 0.0 and (a <= 0.0 or b > a):
                        fired.append(j)
            if fired:
                budget -= 1
                if budget == 0:
                    self.event_overflows += 1
                tau, j = min((self._locate(t, y, h, k1, j, g0[j][0], g1[j][0]), j) for j in fired)
                y, quad = self._rk4(t, y, tau, k1)
                for i in range(3):
                    acc[i] += quad[i]
                t += tau
                self._transition(t, g0[j][1], y)
                self._settle(t, y)
            else:
                y = y1
                for i in range(3):
                    acc[i] += quad[i]
                t += h
                if self.zero:
                    self._project(y)
            k1 = self.rhs(t, *y)
            self._note_knee_sides()
            g0 = self.event_values()
        return y

    def _coast(self, t0: float, t1: float, y: list[float], n: int, acc: list[float]
               ) -> list[float] | None:
        """No current anywhere: only the rotor (and bus capacitor) move, the flux is the
        magnet's. None when a conducting path opens within the interval (then the general
        loop locates it)."""
        m, dc, load = self.motor, self.dc, self.load
        pa0, pb0, w, th, v = y
        h = (t1 - t0) / n
        t_a, v_a, slope = self._tl
        v0 = v_a + slope * (t0 - t_a)
        kw, b, ij = load.kw, m.b, m.ij
        locked = load.locked
        for i in range(n):
            t = i * h
            if locked:
                k1w = k2w = k3w = k4w = 0.0
                w = 0.0
            else:
                k1w = -(b * w + v0 + slope * t + kw * w) * ij
                w2 = w + 0.5 * h * k1w
                k2w = -(b * w2 + v0 + slope * (t + 0.5 * h) + kw * w2) * ij
                w3 = w + 0.5 * h * k2w
                k3w = -(b * w3 + v0 + slope * (t + 0.5 * h) + kw * w3) * ij
                w4 = w + h * k3w
                k4w = -(b * w4 + v0 + slope * (t + h) + kw * w4) * ij
            # theta integrates w exactly as RK4 would: w, w2, w3, w4 are the stage speeds.
            th += h / 6.0 * (w + 2.0 * (w + 0.5 * h * k1w) + 2.0 * (w + 0.5 * h * k2w)
                             + w + h * k3w)
            w += h / 6.0 * (k1w + 2.0 * (k2w + k3w) + k4w)
            if dc.dynamic:
                q1 = dc.dv_dt(v, 0.0)
                q2 = dc.dv_dt(v + 0.5 * h * q1, 0.0)
                q3 = dc.dv_dt(v + 0.5 * h * q2, 0.0)
                q4 = dc.dv_dt(v + h * q3, 0.0)
                v += h / 6.0 * (q1 + 2.0 * (q2 + q3) + q4)
        e = m.p * th
        if m.trapezoidal:
            out = [*m.magnet_flux_ab(e)[:2], w, th, v]
        else:
            out = [m.psim * cos(e), m.psim * sin(e), w, th, v]
        self.rhs(t1, *out)
        self._release(self._emf[0], self._emf[1], self.vdc)
        if self.g_release > 0.0:
            return None
        acc[0] += out[0] - pa0
        acc[1] += out[1] - pb0
        return out

    def _locate(self, t: float, y: list[float], h: float, k1: tuple, j: int, ga: float,
                gb: float) -> float:
        """Earliest tau in (0, h] with event j past zero (Illinois regula falsi on the RK4 map)."""
        if ga > 0.0:
            return 0.0
        a, b = 0.0, h
        fa, fb = ga, gb
        side = 0
        tol = 1e-15 + 1e-11 * h
        for _ in range(80):
            if b - a <= tol:
                break
            x = b - fb * (b - a) / (fb - fa) if fb != fa else 0.5 * (a + b)
            if not a < x < b:
                x = 0.5 * (a + b)
            _, _, gx = self._state_after(t, y, x, k1)
            fx = gx[j][0]
            if fx > 0.0:
                b, fb = x, fx
                if side == 1:
                    fa *= 0.5
                side = 1
            else:
                a, fa = x, fx
                if side == -1:
                    fb *= 0.5
                side = -1
        return b
