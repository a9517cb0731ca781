"""The plant's PWM paths against the independent switched-circuit reference: prints the
figures docs/plant.md and the README quote (phase-current error as a fraction of the peak,
DC-link energy error as a fraction of the energy exchanged, current zero crossings seen).

    python -m bench plant_accuracy            # the four short cases and the 1 s case (minutes)
    python -m bench plant_accuracy --quick    # the four short cases only

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
    return out
