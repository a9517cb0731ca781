"""The plant's C kernel (plant_rt/c/_plantnet.c) and whether it is used.

The extension plant_rt/c/build/_plantnet*.so (``make -C plant_rt/c``, run by
scripts/bootstrap.sh) does the work of the plant's slow paths in one call each:

    integrate    plant_rt.circuit.Network.integrate (the general network over one interval:
                 event-aware RK4, event location, the transitions, the coast with no current)
    settle       the projection and turn-on check of Network.begin
    leg_period   plant_rt.plant.Plant._leg_period (a PWM period as constant-vector pieces,
                 with its sign check)
    duty_period  Plant.step's DUTY period on that path in one call (Plant._duty_step):
                 Command.parse, the switch windows (SwitchTimeline.switch_windows with its
                 dead-time memory), leg_period and Plant._finish; None (nothing changed)
                 hands the period back to the Python code
    sample       plant_rt.plant.Plant.sample with plant_rt.sensors.Sensors.read, the plain
                 case (no sensor fault, no open phase; None otherwise, and when a noise buffer
                 needs its refill: the plant then runs the Python code)
    truth        plant_rt.plant.Plant.truth, the plain case (no open phase, load not locked)

The Python code stays the reference and the fallback: it runs when the extension is not built
(``AVAILABLE`` False, ``UNAVAILABLE_REASON`` says why) or when the environment sets
HIL_PLANT_PURE_PYTHON=1 (read at import). ``KERNEL`` is the module to use, or None. The C code
mirrors the Python operation by operation (compiled with -ffp-contract=off), so the two agree
to rounding (tests/test_plant_c_network.py compares them period by period) and a run with
either is deterministic.

The plant's constants go in as tuples of floats in the order of the kernel's cfg_t, whose
fields say what each is with its unit: plant_rt.motor.MotorModel._k (pole_pairs,
resistance_ohm, flux_linkage_wb, inv_ld_per_h, ...) and plant_rt.circuit.Network._cfg (the
DC link, the inverter's device drop, the load).

Environment: HIL_PLANT_C_PATH loads the extension from another file (the sanitizer build).
"""
from __future__ import annotations

import importlib.machinery
import importlib.util
import os
from pathlib import Path

BUILD_DIR = Path(__file__).resolve().parent / "c" / "build"
#: The interface this module speaks (the extension's ABI constant).
ABI = 6


def extension_path() -> Path:
    """Where the extension is looked for (HIL_PLANT_C_PATH, else plant_rt/c/build/)."""
    override = os.environ.get("HIL_PLANT_C_PATH")
    if override:
        return Path(override).resolve()
    return BUILD_DIR / f"_plantnet{importlib.machinery.EXTENSION_SUFFIXES[0]}"


def load():
    """The extension module (ImportError with the reason when it cannot be loaded)."""
    path = extension_path()
    if not path.is_file():
        raise ImportError(f"the plant's C kernel {path} is not built: run make -C plant_rt/c "
                          f"(or make bootstrap)")
    loader = importlib.machinery.ExtensionFileLoader("plant_rt._plantnet", str(path))
    spec = importlib.util.spec_from_file_location("plant_rt._plantnet", str(path), loader=loader)
    module = importlib.util.module_from_spec(spec)
    loader.exec_module(module)
    if getattr(module, "ABI", None) != ABI:
        raise ImportError(f"{path} was built from another version of _plantnet.c; "
                          f"run make -C plant_rt/c")
    return module


try:
    _ext = load()
except (ImportError, OSError) as exc:
    _ext = None
    AVAILABLE = False
    UNAVAILABLE_REASON = str(exc)
else:
    AVAILABLE = True
    UNAVAILABLE_REASON = ""

#: Set (to anything but "" or "0") to run the Python implementation even with the kernel built.
PURE_PYTHON = os.environ.get("HIL_PLANT_PURE_PYTHON", "") not in ("", "0")
#: The kernel the plant uses by default: the extension, or None (the Python implementation).
KERNEL = None if PURE_PYTHON else _ext
#: The extension whatever HIL_PLANT_PURE_PYTHON says (None when not built), for comparisons.
EXTENSION = _ext
