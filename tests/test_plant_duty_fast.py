"""The DUTY fast path (Plant.step -> the C kernel's duty_period: the switch windows and the
leg-window period in one call) against the code it short-cuts, bit for bit.

Three plants from the same profile and seed take the same commands: one with the fast path (the
default with the kernel built), one with the C kernel but without duty_period (switch_windows,
kernel.duty_windows, _leg_period, kernel.leg_period as before), one in Python (the reference).
After every period their whole state must be identical to the last bit: flux, speed, angle,
revolutions, DC link, the period's integrals, the status flags, the network's legs and events,
the sample and truth records, and the dead-time memory (SwitchTimeline._rise) that the next
period reads. Duties are random, near and at 0 and 1, changed every period or held, with dead
time, device drop and a computation delay, through phase-current zero crossings of both signs;
gate words are mixed in. Cases the fast path must leave to the Python code (a load knot in the
period, a locked rotor, an open phase, a stuck gate, a dynamic link) are counted as such.
"""
from __future__ import annotations

import math
import random
import struct

import pytest

from plant_rt import Plant, ckernel, load_profile

RATED_RAD_S = 3000.0 * 2.0 * math.pi / 60.0

needs_kernel = pytest.mark.skipif(ckernel.EXTENSION is None,
                                  reason=f"C kernel not built: {ckernel.UNAVAILABLE_REASON}")


class WithoutFastPath:
    """The extension without duty_period: the C kernel as it ran DUTY periods before."""

    def __getattr__(self, name):
        if name == "duty_period":
            raise AttributeError(name)
        return getattr(ckernel.EXTENSION, name)


class Kernel(WithoutFastPath):
    """The extension with duty_period's outcomes counted; `call` replaces its call (tests
    break the fast path with it)."""

    def __init__(self, call=None):
        self.call = call or (lambda fn, *args: fn(*args))
        self.outcomes = {"done": 0, "refused": 0, "python": 0}

    def duty_period(self, *args):
        out = self.call(ckernel.EXTENSION.duty_period, *args)
        key = "python" if out is None else "refused" if len(out) == 2 else "done"
        self.outcomes[key] += 1
        return out


def bits(value) -> object:
    """A value with every float replaced by its bytes (so -0.0 != 0.0 and NaN == NaN)."""
    if type(value) is float:
        return struct.pack("<d", value)
    if isinstance(value, (tuple, list)):
        return type(value)(bits(v) for v in value)
    if isinstance(value, dict):
        return {k: bits(v) for k, v in value.items()}
    return value


def snapshot(plant: Plant) -> object:
    net = plant.network
    return bits({
        "state": (plant._pa, plant._pb, plant._w, plant._th, plant._revs, plant._vcap,
                  plant._vdc, plant._u_int, plant._idc_int, plant._flags, plant._zero_current,
                  plant._net_dirty, plant.period),
        "rise": list(plant._timeline._rise),
        "cmd": (plant._cmd.gates, plant._cmd.duty),
        "load": (plant._load_seg, plant._seg_key, plant._load_key),
        "net": (net.events, net.kinds, net.legs_code(), net.all_zero),
        "truth": plant.truth(),
        "sample": tuple(plant.sample()),
    })


def duties(rng: random.Random, n: int, hold: float = 0.0, gates: float = 0.0):
    """n commands: random duties (some at or within 1e-12 of 0 and 1, some held from the last
    period), a fraction of gate words."""
    edge = (0.0, 1.0, 1e-12, 1.0 - 1e-12, 1e-4, 1.0 - 1e-4)
    last = (0.5, 0.5, 0.5)
    for _ in range(n):
        r = rng.random()
        if r < gates:
            yield "gates", rng.choice((0x29, 0x25, 0x26, 0x16, 0x1A, 0x19, 0x2A, 0x15, 0x00))
            continue
        if r < gates + hold:
            yield "duty", last
            continue
        last = tuple(rng.choice(edge) if rng.random() < 0.15 else rng.random() for _ in range(3))
        yield "duty", last


def run(overrides: dict, n: int, seed: int, hold: float = 0.0, gates: float = 0.0,
        setup=None, fast: Kernel | None = None) -> Kernel:
    """Runs the three plants and asserts identical snapshots after every period."""
    overrides = {**overrides}
    overrides.setdefault("initial", {"speed_rad_s": RATED_RAD_S})
    fast = fast or Kernel()
    plants = []
    for kernel in (fast, WithoutFastPath(), False):
        plant = Plant(load_profile(overrides=overrides), seed=0)
        plant.use_c_kernel(kernel)
        if setup is not None:
            setup(plant)
        plants.append(plant)
    for k, (kind, cmd) in enumerate(duties(random.Random(seed), n, hold, gates)):
        for plant in plants:
            if kind == "duty":
                plant.step(duty=cmd)
            else:
                plant.step(gates=cmd)
        a, b, c = (snapshot(p) for p in plants)
        assert a == b, f"fast path != C kernel without it after period {k}: {a} != {b}"
        # (the load caches are filled at other moments by the Python _leg_period)
        b.pop("load"), c.pop("load")
        assert b == c, f"C kernel != Python after period {k}"
    return fast


SCENARIOS = {
    "ideal": {},
    "dead time 1 us": {"inverter": {"dead_time_s": 1e-6}},
    "dead time 2 us, drop 1.5 V": {"inverter": {"dead_time_s": 2e-6, "device_drop_v": 1.5}},
    "delay 10 us": {"timing": {"computation_delay_s": 10e-6}},
    "delay 10 us, dead time 2 us, drop 1.5 V": {
        "timing": {"computation_delay_s": 10e-6},
        "inverter": {"dead_time_s": 2e-6, "device_drop_v": 1.5}},
    "hardware timing (delay T), dead time 1 us": {
        "timing": {"computation_delay_s": 50e-6}, "inverter": {"dead_time_s": 1e-6}},
}


@needs_kernel
@pytest.mark.parametrize("name", list(SCENARIOS))
@pytest.mark.parametrize("speed", [RATED_RAD_S, 0.0])
def test_fast_path_is_bit_identical(name, speed):
    overrides = {**SCENARIOS[name], "initial": {"speed_rad_s": speed}}
    seed = list(SCENARIOS).index(name) + (100 if speed else 0)
    kernel = run(overrides, 600, seed=seed, hold=0.2, gates=0.05)
    assert kernel.outcomes["done"] > 150, kernel.outcomes
    if SCENARIOS[name].get("inverter"):
        # current zero crossings (both signs: every phase reverses in an electrical turn)
        # make the leg-window path refuse periods, which the general network then takes
        assert kernel.outcomes["refused"] > 0, kernel.outcomes


@needs_kernel
def test_fast_path_at_twice_rated_speed_with_drop_through_many_crossings():
    kernel = run({"inverter": {"dead_time_s": 2e-6, "device_drop_v": 1.5},
                  "initial": {"speed_rad_s": 2.0 * RATED_RAD_S}}, 2000, seed=11, hold=0.1)
    assert kernel.outcomes["done"] > 1000 and kernel.outcomes["refused"] > 20, kernel.outcomes


@needs_kernel
def test_load_knots_are_left_to_the_python_code():
    """A load table with a step and a ramp: a period with a knot in it is not the fast path's
    (None, nothing changed), the periods around it are."""
    table = [[0.0, 0.0], [0.003, 0.5], [0.003, -0.2], [0.006, 0.4]]
    kernel = run({"load": {"table": table, "speed_proportional_nm_per_rad_s": 1e-3},
                  "inverter": {"dead_time_s": 1e-6}}, 300, seed=12, hold=0.1)
    assert kernel.outcomes["python"] > 0 and kernel.outcomes["done"] > 200, kernel.outcomes


@needs_kernel
@pytest.mark.parametrize("name, overrides, setup", [
    ("locked rotor", {"load": {"locked": True}, "inverter": {"dead_time_s": 1e-6}}, None),
    ("open phase", {"inverter": {"dead_time_s": 1e-6}}, lambda p: p.set_open_phase("b")),
    ("stuck gate", {}, lambda p: p.set_gate_stuck("a_high", "off")),
    ("dynamic link", {"dc_link": {"source_resistance_ohm": 0.5, "capacitance_f": 1e-3}}, None),
])
def test_cases_outside_the_fast_path_run_the_code_they_ran_before(name, overrides, setup):
    if ckernel.EXTENSION is None:
        pytest.skip(f"C kernel not built: {ckernel.UNAVAILABLE_REASON}")
    kernel = run(overrides, 150, seed=13, setup=setup)
    assert sum(kernel.outcomes.values()) == 0, name


@needs_kernel
def test_runtime_changes_rebind_the_fast_path():
    """A gate stuck and freed, a new dead time, a motor drift and a new load while running."""
    overrides = {"inverter": {"dead_time_s": 1e-6}}
    plants = []
    kernels = [Kernel(), WithoutFastPath(), False]
    for kernel in kernels:
        plant = Plant(load_profile(overrides={**overrides,
                                              "initial": {"speed_rad_s": RATED_RAD_S}}))
        plant.use_c_kernel(kernel)
        plants.append(plant)
    rng = random.Random(14)
    changes = {50: lambda p: p.set_gate_stuck("b_low", "on"),
               60: lambda p: p.set_gate_stuck("b_low", None),
               100: lambda p: p.set_inverter_param("dead_time_s", 2e-6),
               150: lambda p: p.set_motor_param("resistance_ohm", 0.8),
               200: lambda p: p.load.set_speed_proportional(2e-3),
               250: lambda p: p.set_dc_voltage(60.0),
               300: lambda p: p.safe_state()}
    for k in range(350):
        d = (rng.random(), rng.random(), rng.random())
        for plant in plants:
            if k in changes:
                changes[k](plant)
            plant.step(duty=d)
        a, b, c = (snapshot(p) for p in plants)
        assert a == b, k
        b.pop("load"), c.pop("load")
        assert b == c, k
    assert kernels[0].outcomes["done"] > 250


@needs_kernel
@pytest.mark.parametrize("breakage", ["flux one ulp off", "dead-time memory not kept"])
def test_the_comparison_fails_on_a_broken_fast_path(breakage):
    """A fast path whose flux is one ulp off, or that does not update the dead-time memory, is
    caught (the comparison above can fail)."""
    def ulp(fn, *args):
        out = fn(*args)
        if out is not None and len(out) > 2:
            out = (out[0], math.nextafter(out[1], math.inf)) + out[2:]
        return out

    def forgetful(fn, *args):
        args = list(args)
        args[5] = list(args[5])             # SwitchTimeline._rise: a copy is updated
        return fn(*args)

    kernel = Kernel(call=ulp if breakage == "flux one ulp off" else forgetful)
    with pytest.raises(AssertionError, match="fast path != C kernel"):
        run({"inverter": {"dead_time_s": 2e-6}}, 100, seed=15, fast=kernel)
