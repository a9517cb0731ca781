"""The C kernel (plant_rt/c/_plantnet.c) against the Python path, period by period: the figures
docs/plant.md quotes from tests/test_plant_c_network.py, which imports `compare`, `Counting`
and `SCENARIOS` from here (the test asserts 1e-12 and the call counts, this returns the
values). Two plants from the same profile and seed, one per path, take the same commands; the
figure is the worst |C - Python| over the run, per truth field relative to its range (its
largest |value|, at least 1e-9), over all fields. The same comparison with the resistance in
the C calls' arguments alone scaled by 1 + 1e-9 shows that it can fail.
"""
from __future__ import annotations

import math
import random

from bench._rotor_frame_reference import RATED_RAD_S
from plant_rt import TRUTH_FIELDS, Plant, ckernel, load_profile

DROP = {"dead_time_s": 2.0e-6, "device_drop_v": 1.5}
WORDS = (0x29, 0x25, 0x26, 0x16, 0x1A, 0x19, 0x2A, 0x15, 0x28, 0x09, 0x00)


def _relay(name: str, constants: bool = True):
    """A Counting method: counts the call and calls the extension's `name`, with the motor
    constants (the first argument) passed through Counting._k when `constants`."""
    def call(self, *args):
        self.calls[name] += 1
        if constants:
            args = (self._k(args[0]),) + args[1:]
        return getattr(ckernel.EXTENSION, name)(*args)
    call.__name__, call.__qualname__ = name, f"Counting.{name}"
    return call


class Counting:
    """The extension with its calls counted (`calls`: name -> count) and the resistance in
    every call's motor constants scaled by scale_r (1.0: as it is). It has no sample(),
    truth() or duty_period(), so both plants read their truth in Python and the comparison is
    of the integration paths."""

    def __init__(self, scale_r: float = 1.0):
        self.calls = {"integrate": 0, "settle": 0, "leg_period": 0, "advance": 0,
                      "duty_windows": 0, "period": 0, "fast_period": 0, "word_intervals": 0}
        self.scale_r = scale_r

    def _k(self, k):
        if self.scale_r == 1.0:
            return k
        return (k[0], k[1] * self.scale_r) + tuple(k[2:])

    integrate = _relay("integrate")
    settle = _relay("settle")
    leg_period = _relay("leg_period")
    period = _relay("period")
    fast_period = _relay("fast_period")
    advance = _relay("advance")
    word_intervals = _relay("word_intervals", constants=False)
    duty_windows = _relay("duty_windows", constants=False)


def make(kernel, overrides: dict, setup=None) -> Plant:
    """A plant (seed 0, rated speed unless overrides set "initial") on `kernel` (as
    Plant.use_c_kernel takes it), `setup(plant)` applied."""
    overrides = {**overrides}
    overrides.setdefault("initial", {"speed_rad_s": RATED_RAD_S})
    plant = Plant(load_profile(overrides=overrides), seed=0)
    plant.use_c_kernel(kernel)
    if setup is not None:
        setup(plant)
    return plant


def compare(overrides: dict, n: int, seed: int, mode: str = "duty", setup=None,
            kernel=None) -> tuple[float, Counting, Plant, Plant]:
    """Worst |C - Python| over n periods, per signal relative to its range (max |value|,
    >= 1e-9), of two plants taking the same commands (mode "duty": random duties;
    "small_duty": balanced duties 0.5 +- 0.03 turning at 20 rad/s; "gates": random words of
    WORDS; else none). Returns (worst, the kernel (a Counting unless given), the C plant,
    the Python plant)."""
    kernel = kernel or Counting()
    c_plant = make(kernel, overrides, setup)
    py_plant = make(False, overrides, setup)
    rng = random.Random(seed)
    diff = [0.0] * len(TRUTH_FIELDS)
    scale = [1e-9] * len(TRUTH_FIELDS)
    for _ in range(n):
        if mode == "duty":
            d = (rng.random(), rng.random(), rng.random())
            c_plant.step(duty=d)
            py_plant.step(duty=d)
        elif mode == "small_duty":
            # balanced duties 0.5 +- 0.03 turning with the rotor at 20 rad/s, a little noise:
            # sub-ampere currents crossing zero within most periods
            th = 20.0 * c_plant.period * c_plant.control_period_s
            d = tuple(0.5 + 0.03 * math.cos(th - 2.0 * math.pi * x / 3.0) + 0.002 * rng.random()
                      for x in range(3))
            c_plant.step(duty=d)
            py_plant.step(duty=d)
        elif mode == "gates":
            g = rng.choice(WORDS)
            c_plant.step(gates=g)
            py_plant.step(gates=g)
        else:
            c_plant.step()
            py_plant.step()
        for i, (x, y) in enumerate(zip(c_plant.truth(), py_plant.truth())):
            diff[i] = max(diff[i], abs(x - y))
            scale[i] = max(scale[i], abs(y))
    return max(d / s for d, s in zip(diff, scale)), kernel, c_plant, py_plant


#: name -> compare()'s arguments (overrides, n, seed, mode, setup): test_plant_c_network's runs
SCENARIOS = {
    "pwm_dead_time_drop_rated": ({"inverter": DROP, "initial": {"speed_rad_s": RATED_RAD_S}},
                                 1500, 1, "duty", None),
    "pwm_dead_time_drop_twice_rated": ({"inverter": DROP,
                                        "initial": {"speed_rad_s": 2.0 * RATED_RAD_S}},
                                       1500, 1, "duty", None),
    "pwm_dead_time_from_standstill": ({"inverter": {"dead_time_s": 1.0e-6},
                                       "initial": {"speed_rad_s": 0.0}}, 1500, 2, "duty", None),
    "pwm_dead_time_low_speed_small_current": ({"inverter": {"dead_time_s": 1.0e-6},
                                               "initial": {"speed_rad_s": 20.0}},
                                              1500, 3, "small_duty", None),
    "safe_state_twice_rated": ({"inverter": DROP, "initial": {"speed_rad_s": 2 * RATED_RAD_S}},
                               2000, 3, "none", lambda p: p.safe_state()),
    "gate_words_full_period_delay": ({"timing": {"computation_delay_s": 50e-6},
                                      "inverter": DROP}, 1000, 4, "gates", None),
    "open_phase": ({"inverter": DROP}, 1000, 4, "gates", lambda p: p.set_open_phase("b")),
    "dynamic_link": ({"dc_link": {"source_resistance_ohm": 0.5, "capacitance_f": 1e-3,
                                  "unidirectional": True}}, 1000, 4, "gates", None),
    "resistive_link": ({"dc_link": {"source_resistance_ohm": 0.5}}, 1000, 4, "duty", None),
    "locked_rotor": ({"load": {"locked": True}, "inverter": DROP}, 1000, 4, "duty", None),
    "load_table_with_a_step": ({"load": {"table": [[0.0, 0.0], [0.02, 1.0], [0.02, -0.5],
                                                   [0.04, 0.3]],
                                         "speed_proportional_nm_per_rad_s": 1e-3},
                                "inverter": DROP}, 1000, 4, "duty", None),
    "interior_magnet": ({"motor": {"inductance_q_h": 9e-3}, "inverter": {"dead_time_s": 2e-6}},
                        1000, 4, "gates", None),
}
#: compare()'s arguments of the run with the resistance in the C calls scaled by 1 + 1e-9
PERTURBED = ({"inverter": DROP}, 400, 5)
QUICK = ("pwm_dead_time_drop_rated", "safe_state_twice_rated")


def run(quick: bool = False) -> dict:
    """{"worst_of_range": {scenario: worst}, "bit_identical": all zero,
    "perturbed_resistance_1e-9": worst with R scaled in the C calls}; quick: two scenarios."""
    if ckernel.EXTENSION is None:
        return {"skipped": f"C kernel not built: {ckernel.UNAVAILABLE_REASON}"}
    names = [n for n in SCENARIOS if not quick or n in QUICK]
    worst = {n: float(f"{compare(*SCENARIOS[n])[0]:.2g}") for n in names}
    perturbed = compare(*PERTURBED, kernel=Counting(1 + 1e-9))[0]
    return {"worst_of_range": worst, "bit_identical": all(v == 0.0 for v in worst.values()),
            "perturbed_resistance_1e-9": float(f"{perturbed:.2g}")}
