"""Two-level three-leg voltage-source inverter: gate commands to switch timing and leg states.

The switch word has one bit per switch, per leg one high-side and one low-side switch
(SWITCH_* below). It is the same layout as the protocol's GATES word (protocol/SPEC.md,
HIL_GATE_*), so the bench hands a board's word to the plant unchanged; the plant itself knows
nothing of the protocol (tests/test_architecture.py checks that the two layouts agree). A leg with exactly one switch on ties its phase terminal to DC+ (H) or DC- (L); a leg
with both off (dead time, or a command that opens it) conducts through its diodes according to
the current direction, and carries no current once that current has reached zero; a leg with
both on is a shoot-through, which the gate driver's desaturation protection answers by turning
the leg off (it is then open and the sample's GATE_FAULT bit is set).

With the star point floating, a complementary switching state (s_a s_b s_c) gives the paper's
Table 2 vector u = 2/3 U_dc (s_a + s_b e^{j2pi/3} + s_c e^{j4pi/3}); V1(100) is A high, B low,
C low.

Timing within a control period [0, T): the command of the previous period holds until the
computation delay, the new one after it. A duty command is a centre-aligned PWM period aligned
with the control period (carrier valley at the sampling instant t_k): the high side of a leg is
on during [T (1 - d)/2, T (1 + d)/2), the low side the rest of the period. Dead time delays
every switch's turn-on edge by dead_time_s. A duty command may float legs (its leg enables,
``legs``, bit x for leg x): a floated leg has both switches off for the whole period and conducts
through its diodes like any open leg. The result is a list of intervals with a constant
switch word, integrated one after the other (segment by segment, never averaged).
"""
from __future__ import annotations

import math
import operator
from configfile.dataclass_methods import dataclass

from configfile.fields import param

#: Switch bits of the switch word, 1 = switch on.
SWITCH_A_HIGH = 0x01
SWITCH_A_LOW = 0x02
SWITCH_B_HIGH = 0x04
SWITCH_B_LOW = 0x08
SWITCH_C_HIGH = 0x10
SWITCH_C_LOW = 0x20

LEG_BITS = ((SWITCH_A_HIGH, SWITCH_A_LOW), (SWITCH_B_HIGH, SWITCH_B_LOW),
            (SWITCH_C_HIGH, SWITCH_C_LOW))

#: Leg enables of a duty command: bit x = leg x (a, b, c) switches; a leg whose bit is 0 is
#: floated (both switches off all period).
ALL_LEGS = 0x07

#: Table 2 switching states (s_a s_b s_c), 1 = high side on, as gate words.
VECTOR_GATES = {
    "V0": 0x2A, "V1": 0x29, "V2": 0x25, "V3": 0x26, "V4": 0x16, "V5": 0x1A, "V6": 0x19, "V7": 0x15,
}

# Leg states within an interval.
H, L, P, N, O = 0, 1, 2, 3, 4   # driven high, driven low, open with i > 0 / i < 0 / i == 0
OPEN = (P, N, O)

SQRT3 = math.sqrt(3.0)
#: Unit phase axes in the stationary frame: i_x = e_x . i_alphabeta (amplitude-invariant).
PHASE_AXES = ((1.0, 0.0), (-0.5, 0.5 * SQRT3), (-0.5, -0.5 * SQRT3))


@dataclass(frozen=True)
class InverterParams:
    """Switching non-idealities; the defaults are the paper's ideal inverter."""

    dead_time_s: float = param(0.0, ge=0)
    device_drop_v: float = param(0.0, ge=0)
    device_knee_a: float = param(0.1, gt=0)


def leg_states(word: int) -> tuple[int, int, int]:
    """Per leg H, L or O (O: both switches off, or both on and tripped by desaturation)."""
    out = []
    for hi, lo in LEG_BITS:
        on_h, on_l = bool(word & hi), bool(word & lo)
        out.append(H if on_h and not on_l else L if on_l and not on_h else O)
    return out[0], out[1], out[2]


def shoot_through(word: int) -> bool:
    return any((word & hi) and (word & lo) for hi, lo in LEG_BITS)


def driven_vector(word: int, vdc: float) -> tuple[float, float, float, float] | None:
    """(u_alpha, u_beta, g_alpha, g_beta) for a word that drives all three legs, else None.

    u is Table 2's voltage; g = sum of the axes of the legs tied to DC+, so the DC-link current
    is g . i_alphabeta.
    """
    states = leg_states(word)
    if any(s not in (H, L) for s in states):
        return None
    sa, sb, sc = (1.0 if s == H else 0.0 for s in states)
    ga = sum(PHASE_AXES[x][0] for x in range(3) if states[x] == H)
    gb = sum(PHASE_AXES[x][1] for x in range(3) if states[x] == H)
    return (vdc * (2.0 * sa - sb - sc) / 3.0, vdc * (sb - sc) / SQRT3, ga, gb)


class Command:
    """A controller command: a gate word, or three duty cycles with their leg enables
    (``legs``, ALL_LEGS unless legs are floated). Immutable, comparable."""

    __slots__ = ("gates", "duty", "legs")

    def __init__(self, gates: int | None = None, duty: tuple[float, float, float] | None = None,
                 legs: int = ALL_LEGS):
        self.gates = gates
        self.duty = duty
        self.legs = legs

    def __eq__(self, other: object) -> bool:
        return (isinstance(other, Command) and self.gates == other.gates
                and self.duty == other.duty and self.legs == other.legs)

    def __hash__(self) -> int:
        return hash((self.gates, self.duty, self.legs))

    def __repr__(self) -> str:
        if self.duty is None:
            return f"Command(gates={self.gates!r})"
        if self.legs != ALL_LEGS:
            return f"Command(duty={self.duty!r}, legs={self.legs:#05b})"
        return f"Command(duty={self.duty!r})"

    @staticmethod
    def parse(gates: int | None, duty, legs: int | None = None) -> "Command | None":
        if gates is not None and duty is not None:
            raise ValueError("step() takes gates or duty, not both")
        if legs is not None:
            try:
                mask = operator.index(legs)
            except TypeError:
                mask = -1
            if isinstance(legs, bool) or not 0 <= mask <= ALL_LEGS:
                raise ValueError(f"legs must be an int 0..7 of leg enables (bit x = leg x), got {legs!r}")
            if duty is None:
                raise ValueError("legs (leg enables) go with duty, not with gates")
        if gates is not None:
            try:
                word = operator.index(gates)        # numpy integers too, not floats
            except TypeError:
                word = -1
            if isinstance(gates, bool) or not 0 <= word <= 0x3F:
                raise ValueError(f"gates must be an int 0..0x3F of SWITCH_* bits, got {gates!r}")
            return GATE_COMMANDS[word]
        if duty is not None:
            try:
                a, b, c = duty       # unpacked, not a generator: this runs every PWM period
                values = (float(a), float(b), float(c))
            except (TypeError, ValueError):
                raise ValueError(f"duty must be three numbers 0..1, got {duty!r}") from None
            if not (0.0 <= values[0] <= 1.0 and 0.0 <= values[1] <= 1.0
                    and 0.0 <= values[2] <= 1.0):
                raise ValueError(f"duty must be three numbers 0..1, got {duty!r}")
            return Command(duty=values, legs=ALL_LEGS if legs is None else mask)
        return None

    def edges(self, switch: int, period_s: float) -> tuple[bool, tuple[float, ...]]:
        """(state at 0+, toggle times in (0, T)) of one switch (0..5 = A_H, A_L, B_H, ...)."""
        leg, low = divmod(switch, 2)
        if self.duty is None:
            return bool(self.gates & LEG_BITS[leg][low]), ()
        if not self.legs >> leg & 1:
            return False, ()                # a floated leg: both switches off all period
        d = self.duty[leg]
        if d <= 0.0:
            return bool(low), ()
        if d >= 1.0:
            return not low, ()
        return bool(low), (0.5 * period_s * (1.0 - d), 0.5 * period_s * (1.0 + d))


def _drop_glitches(toggles: list[float], min_width: float) -> list[float]:
    """Removes pulses narrower than min_width (an edge of the new command landing on the
    computation delay up to rounding), which no gate driver would pass."""
    out: list[float] = []
    for t in toggles:
        if out and t - out[-1] < min_width:
            out.pop()
        else:
            out.append(t)
    return out


#: One shared Command per gate word, so an unchanged command is recognised by identity.
GATE_COMMANDS = tuple(Command(gates=g) for g in range(64))


class SwitchTimeline:
    """Builds each period's constant-word intervals from the old and new command.

    Remembers, per switch, when its command last turned it on (relative to the current period
    start) so that dead time spans period boundaries. ``force_on`` and ``force_off`` (gate
    bits) are switches stuck on or off whatever they are told (a fault): applied to every
    interval's word, after dead time, so a stuck-on switch meeting its commanded partner is a
    shoot-through like any other.

    ``kernel``: the plant's C kernel (plant_rt.ckernel), which then computes _duty_windows and
    the word intervals' sweep;
    None (the default) keeps the Python code.
    """

    kernel = None

    def __init__(self, period_s: float, delay_s: float, dead_time_s: float):
        self.period_s = period_s
        self.delay_s = delay_s
        self.dead_time_s = dead_time_s
        self.force_on = 0
        self.force_off = 0
        # Per switch: time of the command's last rising edge (<= 0), or None while commanded off.
        self._rise: list[float | None] = [None] * 6

    def _stuck(self, intervals: list[tuple[float, float, int]]) -> list[tuple[float, float, int]]:
        on, keep = self.force_on, ~self.force_off
        if not (on or self.force_off):
            return intervals
        return [(a, b, (word | on) & keep) for a, b, word in intervals]

    def reset(self, command: Command) -> None:
        """The command has held forever (e.g. safe state): no pending dead time."""
        for j in range(6):
            on, _ = command.edges(j, self.period_s)
            self._rise[j] = -math.inf if on else None

    def trivial(self, old: Command, new: Command) -> bool:
        """True when the whole period is one interval with new.gates (the common fast case)."""
        return (new.duty is None and self.dead_time_s == 0.0
                and (self.delay_s == 0.0 or old == new))

    def build(self, old: Command, new: Command) -> list[tuple[float, float, int]]:
        """[(start, end, word), ...] covering [0, T), times relative to the period start."""
        T = self.period_s
        if self.dead_time_s == 0.0 and (self.delay_s == 0.0 or old == new):
            if new.duty is None:
                return self._stuck([(0.0, T, new.gates)])
            return self._stuck(self._duty_sweep(new.duty, new.legs))
        return self.words(self.switch_windows(old, new))

    def words(self, windows: list[list[tuple[float, float]]]) -> list[tuple[float, float, int]]:
        """The constant-word intervals of switch_windows()' on-intervals (stuck bits applied)."""
        sweep = getattr(self.kernel, "word_intervals", None)
        if sweep is not None:
            intervals = sweep(self.period_s, windows)
            if intervals is not None:       # (None: more toggles than the kernel holds)
                return self._stuck(intervals)
        return self._stuck(self._word_intervals(windows))

    def switch_windows(self, old: Command, new: Command) -> list[list[tuple[float, float]]]:
        """Per switch (A_H, A_L, B_H, ...) its on-intervals [(a, b), ...] in [0, T), dead time
        applied, stuck bits not. Advances the dead-time memory: call once per period."""
        T = self.period_s
        if new.duty is not None and (self.delay_s == 0.0 or old == new):
            return self._duty_windows(new.duty, new.legs)
        delay = min(self.delay_s, T)
        td = self.dead_time_s
        actual: list[list[tuple[float, float]]] = []
        for j in range(6):
            state0, old_edges = old.edges(j, T)
            new_state0, new_edges = new.edges(j, T)
            # Command state as a list of toggles on [0, T).
            toggles: list[float] = []
            if delay > 0.0:
                start = state0
                toggles.extend(t for t in old_edges if t < delay)
                state_at_delay = state0 ^ (len(toggles) % 2 == 1)
                new_at_delay = new_state0 ^ (sum(1 for t in new_edges if t <= delay) % 2 == 1)
                if delay < T and state_at_delay != new_at_delay:
                    toggles.append(delay)
                toggles.extend(t for t in new_edges if delay < t < T)
            else:
                start = new_state0
                toggles.extend(new_edges)
            toggles = _drop_glitches(toggles, 1e-9 * T)
            # On-intervals of the command, then of the switch (turn-on delayed by td).
            intervals = []
            on = start
            rise = None
            if start:
                rise = self._rise[j] if self._rise[j] is not None else 0.0
            for t in toggles:
                if on:
                    intervals.append((rise, t))
                    rise = None
                else:
                    rise = t
                on = not on
            if on:
                intervals.append((rise, T))
                self._rise[j] = rise - T
            else:
                self._rise[j] = None
            switch_on = []
            for a, b in intervals:
                a = max(a + td, 0.0)
                if a < b:
                    switch_on.append((a, b))
            actual.append(switch_on)
        return actual

    def _duty_windows(self, duty: tuple[float, float, float], legs: int = ALL_LEGS
                      ) -> list[list[tuple[float, float]]]:
        """switch_windows() for a duty command with no delay in play (the common case): the
        command of switch j is on in one centre window (high side) or around it (low side);
        turn-on edges come td later, a command that has been on since the last period keeps
        the rise it had (dead time across the period boundary). A floated leg (its bit of
        ``legs`` 0) has no window and forgets its rises."""
        if self.kernel is not None:
            if legs == ALL_LEGS:
                return self.kernel.duty_windows(self.period_s, self.dead_time_s, duty, self._rise)
            return self.kernel.duty_windows(self.period_s, self.dead_time_s, duty, self._rise, legs)
        T = self.period_s
        td = self.dead_time_s
        rise = self._rise
        out: list[list[tuple[float, float]]] = []
        for x in range(3):
            d = duty[x]
            jh, jl = 2 * x, 2 * x + 1
            if not legs >> x & 1:
                out.append([])
                out.append([])
                rise[jh] = None
                rise[jl] = None
                continue
            if d >= 1.0:
                r = rise[jh]
                a = td if r is None else max(r + td, 0.0)
                out.append([(a, T)] if a < T else [])
                rise[jh] = (0.0 if r is None else r) - T
                rise[jl] = None
                out.append([])
                continue
            if d <= 0.0:
                r = rise[jl]
                a = td if r is None else max(r + td, 0.0)
                out.append([])
                out.append([(a, T)] if a < T else [])
                rise[jh] = None
                rise[jl] = (0.0 if r is None else r) - T
                continue
            t_on = 0.5 * T * (1.0 - d)
            t_off = 0.5 * T * (1.0 + d)
            a = t_on + td
            out.append([(a, t_off)] if a < t_off else [])
            rise[jh] = None
            low = []
            r = rise[jl]
            a = td if r is None else max(r + td, 0.0)
            if a < t_on:
                low.append((a, t_on))
            a = t_off + td
            if a < T:
                low.append((a, T))
            rise[jl] = t_off - T
            out.append(low)
        return out

    def _duty_sweep(self, duty: tuple[float, float, float], legs: int = ALL_LEGS
                    ) -> list[tuple[float, float, int]]:
        """One centre-aligned period without dead time: legs switch at T (1 -+ d) / 2; a
        floated leg keeps both switches off."""
        T = self.period_s
        word = 0
        toggles = []
        for x, d in enumerate(duty):
            hi, lo = LEG_BITS[x]
            if not legs >> x & 1:
                continue
            if d >= 1.0:
                word |= hi
            elif d <= 0.0:
                word |= lo
            else:
                word |= lo
                toggles.append((0.5 * T * (1.0 - d), hi | lo))
                toggles.append((0.5 * T * (1.0 + d), hi | lo))
        toggles.sort()
        out = []
        t = 0.0
        for when, mask in toggles:
            if when > t:
                out.append((t, when, word))
                t = when
            word ^= mask
        out.append((t, T, word))
        return out

    def _word_intervals(self, actual: list[list[tuple[float, float]]]
                        ) -> list[tuple[float, float, int]]:
        """Sweeps the six switches' on-intervals into constant-word intervals."""
        T = self.period_s
        word = 0
        toggles = []
        for j, switch_on in enumerate(actual):
            bit = 1 << j
            for a, b in switch_on:
                if a <= 0.0:
                    word |= bit
                else:
                    toggles.append((a, bit))
                if b < T:
                    toggles.append((b, bit))
        toggles.sort()
        out: list[tuple[float, float, int]] = []
        t = 0.0
        for when, bit in toggles:
            if when > t:
                if out and out[-1][2] == word:
                    out[-1] = (out[-1][0], when, word)
                else:
                    out.append((t, when, word))
                t = when
            word ^= bit
        if out and out[-1][2] == word:
            out[-1] = (out[-1][0], T, word)
        else:
            out.append((t, T, word))
        return out
