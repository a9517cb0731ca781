"""A duty command with floated legs (the plant's side of DUTY_LEGS, SPEC 6.12).

Reference: the same control period driven as the equivalent sequence of gate words, on a plant
whose control period is T/8, so that every PWM edge (duties in multiples of 1/4) falls on a
sub-period boundary: leg x high while T (1 - d_x)/2 <= t < T (1 + d_x)/2, low otherwise, both
switches off when floated. The two plants share nothing but the motor: one turns duties and leg
enables into switch windows (Command, SwitchTimeline, the leg-window path or the network), the
other only ever sees whole-period gate words. Both the Python plant and the C kernel are checked;
the C paths (with and without the kernel's duty_period fast path) must also equal the Python
reference bit for bit, period by period, with dead time and a computation delay.
"""
from __future__ import annotations

import random

import pytest

from plant_rt import Plant, ckernel, load_profile
from plant_rt.inverter import ALL_LEGS, Command

try:  # tests/ as a package, or as a plain directory on sys.path
    from tests.test_plant_duty_fast import SCENARIOS, Kernel, WithoutFastPath, snapshot
except ImportError:
    from test_plant_duty_fast import SCENARIOS, Kernel, WithoutFastPath, snapshot

T = 50e-6
SUB = 8                                     # gate-word sub-periods per PWM period
KERNELS = [pytest.param(False, id="python")] + ([pytest.param(True, id="c")] if ckernel.AVAILABLE else [])

# Six-step-like commands: one leg PWM, one leg at a rail, one floated, rotating; then all legs
# switching, and all floated (the motor coasts through the diodes).
COMMANDS = [((0.5, 0.0, 0.0), 0b011), ((0.75, 0.0, 0.0), 0b011), ((0.25, 0.0, 0.0), 0b101),
            ((0.0, 0.5, 0.0), 0b110), ((0.5, 1.0, 0.0), 0b110), ((0.0, 0.0, 0.75), 0b101),
            ((0.5, 0.25, 0.75), ALL_LEGS), ((0.5, 0.5, 0.5), 0b000)]


def plant(period_s: float, kernel, speed_rad_s: float) -> Plant:
    p = Plant(load_profile(overrides={"timing": {"control_period_s": period_s},
                                      "initial": {"speed_rad_s": speed_rad_s}}), seed=0)
    p.use_c_kernel(kernel)
    return p


def gate_words(duty: tuple[float, float, float], legs: int) -> list[int]:
    """The period as SUB gate words (SPEC 1.1's centre-aligned PWM; bit 2x high, 2x+1 low)."""
    words = []
    for k in range(SUB):
        t = (k + 0.5) * T / SUB             # the middle of the sub-period: no edge there
        word = 0
        for x in range(3):
            if legs >> x & 1:
                high = T * (1 - duty[x]) / 2 <= t < T * (1 + duty[x]) / 2
                word |= (1 << 2 * x) if high else (2 << 2 * x)
        words.append(word)
    return words


@pytest.mark.parametrize("kernel", KERNELS)
@pytest.mark.parametrize("speed_rad_s", [150.0, 400.0])
def test_floated_leg_duty_equals_the_gate_word_sequence(kernel, speed_rad_s):
    rng = random.Random(7)
    duty_plant, gates_plant = plant(T, kernel, speed_rad_s), plant(T / SUB, kernel, speed_rad_s)
    floated_current_seen = 0.0
    for n in range(120):
        duty, legs = COMMANDS[n // 4 % len(COMMANDS)] if n < 96 else rng.choice(COMMANDS)
        duty_plant.step(duty=duty, legs=legs)
        for word in gate_words(duty, legs):
            gates_plant.step(gates=word)
        a, b = duty_plant.truth(), gates_plant.truth()
        assert a[0] == pytest.approx(b[0], abs=1e-12)
        # phase currents (A), fluxes (Wb), speed (rad/s), angle (rad): integration tolerance
        assert a[1:4] == pytest.approx(b[1:4], abs=1e-6), f"period {n}: currents"
        assert a[6:8] == pytest.approx(b[6:8], abs=1e-9), f"period {n}: flux"
        assert a[10] == pytest.approx(b[10], abs=1e-6) and a[13] == pytest.approx(b[13], abs=1e-9)
        for x in range(3):
            if not legs >> x & 1:
                floated_current_seen = max(floated_current_seen, abs(a[1 + x]))
    # a floated leg's current free-wheeled through a diode at some point: the diode path ran
    assert floated_current_seen > 0.05


@pytest.mark.parametrize("kernel", KERNELS)
def test_all_legs_floated_is_all_switches_off(kernel):
    """legs 0: the analytic case of an open bridge: with no current and the line back-EMF below
    the DC link, no current flows at all (the plant coasts exactly as under GATES 0)."""
    floated, opened = plant(T, kernel, 50.0), plant(T, kernel, 50.0)
    for _ in range(40):
        floated.step(duty=(0.5, 0.5, 0.5), legs=0)
        opened.step(gates=0)
        a, b = floated.truth(), opened.truth()
        assert a[1:4] == (0.0, 0.0, 0.0)
        assert a == b


def test_legs_are_checked_and_go_with_duty():
    with pytest.raises(ValueError, match="legs must be an int 0..7"):
        Command.parse(None, (0.5, 0.5, 0.5), 8)
    with pytest.raises(ValueError, match="legs must be an int 0..7"):
        Command.parse(None, (0.5, 0.5, 0.5), True)
    with pytest.raises(ValueError, match="go with duty"):
        Command.parse(0x29, None, 3)
    assert Command.parse(None, (0.5, 0.5, 0.5), None) == Command.parse(None, (0.5, 0.5, 0.5), ALL_LEGS)
    assert Command.parse(None, (0.5, 0.5, 0.5), 3) != Command.parse(None, (0.5, 0.5, 0.5), ALL_LEGS)


@pytest.mark.skipif(ckernel.EXTENSION is None, reason=f"C kernel not built: {ckernel.UNAVAILABLE_REASON}")
@pytest.mark.parametrize("name", list(SCENARIOS))
def test_floated_legs_same_bits_in_python_and_c(name):
    """Fast path, C kernel without it, Python: the same state after every period, to the bit,
    with random duties and leg enables (held or changed) through dead time, drop and delay."""
    overrides = {**SCENARIOS[name], "initial": {"speed_rad_s": 200.0}}
    fast = Kernel()
    plants = []
    for kernel in (fast, WithoutFastPath(), False):
        p = Plant(load_profile(overrides=overrides), seed=0)
        p.use_c_kernel(kernel)
        plants.append(p)
    rng = random.Random(11)
    duty, legs = (0.5, 0.5, 0.5), ALL_LEGS
    for k in range(300):
        if rng.random() < 0.7:
            duty = tuple(rng.choice((0.0, 1.0)) if rng.random() < 0.15 else rng.random() for _ in range(3))
            legs = rng.choice((0b011, 0b101, 0b110, ALL_LEGS, 0b001, 0))
        for p in plants:
            p.step(duty=duty, legs=legs)
        a, b, c = ((snapshot(p), p._cmd.legs) for p in plants)
        assert a == b, f"fast path != C kernel without it after period {k}"
        b[0].pop("load"), c[0].pop("load")  # (the load caches are filled at other moments in Python)
        assert b == c, f"C kernel != Python after period {k}"
    assert fast.outcomes["done"] > 0     # the fast path took floated-leg periods itself
