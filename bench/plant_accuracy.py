"""The plant's PWM paths against the independent switched-circuit reference: prints the
figures docs/plant.md and the README quote (phase-current error as a fraction of the peak,
DC-link energy error as a fraction of the energy exchanged, current zero crossings seen).

    python -m bench plant_accuracy            # every case, the 1 s runs included (about 5 min)
    python -m bench plant_accuracy --quick    # without the 1 s runs, 2 of 12 C-kernel scenarios
                                              # (under a minute)

`solve_ivp_rotor_frame` adds the gate-word path against solve_ivp of the rotor-frame equations
(bench/_rotor_frame_reference.py, which tests/test_plant_accuracy.py asserts limits on;
about 40 s, quick about 8 s). `physics` adds the safe state and the diode bridge against
per-phase diode-circuit references, the locked rotor, six-step speed, energy balances and the
dead-time voltage error (bench/_plant_accuracy_physics.py, the runs of
tests/test_plant_accuracy.py and tests/test_plant_physics.py); `c_kernel_vs_python` the C
kernel against the Python path (bench/_plant_accuracy_ckernel.py, the runs of
tests/test_plant_c_network.py).

The reference and the comparison are bench/_switched_reference.py's (scipy solve_ivp,
rtol 1e-10, on the circuit written from its equations, not from the plant's code); the tests
assert the limits (1e-6 of each), this prints the values. It runs whichever plant path is the
default: the C kernel when it is built (plant_rt.ckernel), else the Python reference.
"""
from __future__ import annotations

from plant_rt import ckernel


def run(quick: bool = False) -> dict:
    from bench._switched_reference import RATED_RAD_S, run as compare

    cases = {
        "dead_time_2us_rated": (RATED_RAD_S, 1200, 1, 2e-6, 0.0),
        "dead_time_2us_twice_rated": (2 * RATED_RAD_S, 1200, 1, 2e-6, 0.0),
        "dead_time_2us_drop_1v5_rated": (RATED_RAD_S, 1200, 2, 2e-6, 1.5),
        "dead_time_2us_drop_1v5_twice_rated": (2 * RATED_RAD_S, 1200, 3, 2e-6, 1.5),
    }
    if not quick:
        cases["one_second_dead_time_2us_drop_1v5_twice_rated"] = (2 * RATED_RAD_S, 20000, 5, 2e-6, 1.5)
    out: dict = {"plant_path": "C kernel" if ckernel.AVAILABLE else "Python"}
    for name, (speed, periods, seed, td, drop) in cases.items():
        result = compare(speed, periods, seed=seed, td=td, drop=drop)
        out[name] = {"periods": periods, "current_error_of_peak": float(f"{result['current_rel']:.2g}"),
                     "energy_error": float(f"{result['energy_rel']:.2g}"),
                     "zero_crossings": result["crossings"]}
    out["solve_ivp_rotor_frame"] = solve_ivp_figures(quick)
    out["physics"] = physics_figures(quick)
    out["c_kernel_vs_python"] = c_kernel_figures(quick)
    return out


def physics_figures(quick: bool = False) -> dict:
    """The plant against analytic results and diode-circuit references, as
    tests/test_plant_accuracy.py and tests/test_plant_physics.py compute them (they assert
    the limits; this prints the values docs/plant.md quotes). About 4 s, quick the same."""
    from bench._plant_accuracy_physics import run as physics

    return physics(quick)


def c_kernel_figures(quick: bool = False) -> dict:
    """The C kernel against the Python path, tests/test_plant_c_network.py's scenarios and
    measure (worst difference per truth field relative to its range; the test asserts 1e-12),
    and the same comparison with the resistance scaled by 1 + 1e-9 in the C calls alone.
    About 7 s; quick: two of the twelve scenarios."""
    from bench._plant_accuracy_ckernel import run as c_kernel

    return c_kernel(quick)


def solve_ivp_figures(quick: bool = False) -> dict:
    """The gate-word path against solve_ivp (DOP853, rtol 1e-10) of the rotor-frame current
    equations: bench/_rotor_frame_reference.py's three cases (tests/test_plant_accuracy.py
    asserts the limits, 1e-5 of the peak and 1e-6; this prints the values that docs/plant.md
    quotes). Full: 1 s of random gates sweeping 0.3x to 2x rated speed, Ld != Lq
    at 2x rated (0.15 s), 4 pole pairs (0.1 s); quick: the last two only."""
    from bench._rotor_frame_reference import CASES, run_against_reference

    quick_cases = ("ld_ne_lq_twice_rated", "four_pole_pairs")
    cases = {name: args for name, args in CASES.items() if not quick or name in quick_cases}
    out = {}
    for name, (overrides, duration, w0, w1, seed, share) in cases.items():
        r = run_against_reference(overrides, duration, w0, w1, seed, share)
        out[name] = {"current_error_of_peak": float(f"{r['current_rel']:.2g}"),
                     "speed_error_relative": float(f"{r['speed_rel']:.2g}"),
                     "angle_error_rad": float(f"{r['angle_rad']:.2g}"),
                     "peak_a": round(float(r["peak_a"]), 1)}
    return out
