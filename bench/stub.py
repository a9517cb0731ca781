"""Controller-stub figures: instructions per control step and the Cortex-M4F code size.

Instructions are counted by valgrind's callgrind (repeatable on a noisy machine)
on firmware_stub/build/step_driver, which runs ctl_step over a fixed synthetic
sample sequence in each speed-source mode. Two ways, which must agree:
``toggle`` counts only inside ctl_step (--toggle-collect=ctl_step);
``difference`` is the whole program minus a baseline run that does everything
but call ctl_step (its stand-in's 2 instructions per call aside). Each mode is
counted with telemetry filled every step (TELEMETRY adds the eq. (24)-(26) rotor
position and the record itself), without telemetry (what most periods cost at
the default divider of 10), and averaged at that divider.

The Cortex-M4F code size is arm-none-eabi-size of the core alone and of core +
application layer + protocol codec, built with ``make -C firmware_stub arm``.

``closed_loop`` drives the plant emulator's Table 1 motor with the stub (in
process, every protocol byte through the C codec) for a 0 -> 1500 -> 3000 rpm
speed profile with each speed source closing the loop, and compares the
estimates with the plant's truth (deterministic: fixed seeds, lockstep).
"""
from __future__ import annotations

import re
import shutil
import subprocess
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
STUB = REPO / "firmware_stub"
DRIVER = STUB / "build" / "step_driver"
ARM_CORE = STUB / "build" / "arm" / "libhilstub_core_m4.a"
ARM_ALL = STUB / "build" / "arm" / "libhilstub_m4.a"
MODES = {"encoder": 0, "conventional": 1, "ekf": 2}
DEFAULT_TELEMETRY_DIVIDER = 10


def _collected(args: list[str], toggle: bool) -> int:
    """Instructions callgrind counts for one run of the driver."""
    with tempfile.TemporaryDirectory() as tmp:
        cmd = ["valgrind", "--tool=callgrind", f"--callgrind-out-file={tmp}/out"]
        if toggle:
            cmd.append("--toggle-collect=ctl_step")
        proc = subprocess.run(cmd + [str(DRIVER), *args], capture_output=True, text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"step_driver {' '.join(args)} under callgrind failed:\n{proc.stderr}")
    m = re.search(r"Collected : (\d+)", proc.stderr)
    if m is None:
        raise RuntimeError(f"no callgrind total in:\n{proc.stderr}")
    return int(m.group(1))


def instructions_per_step(mode: int, steps: int, telemetry_every: int) -> dict[str, float]:
    args = [str(mode), str(steps), str(telemetry_every)]
    toggle = _collected(args, toggle=True) / steps
    difference = (_collected(args, toggle=False) - _collected(args + ["baseline"], toggle=False)) / steps
    return {"toggle": round(toggle, 2), "difference": round(difference, 2)}


def arm_sizes() -> dict[str, dict[str, int]]:
    out = {}
    for name, lib in (("core", ARM_CORE), ("core_app_codec", ARM_ALL)):
        text = subprocess.run(["arm-none-eabi-size", "-t", str(lib)], capture_output=True, text=True,
                              check=True).stdout.strip().splitlines()[-1].split()
        out[name] = {"text": int(text[0]), "data": int(text[1]), "bss": int(text[2])}
    return out


def closed_loop(source: int, seconds_per_step: float = 0.3) -> dict[str, float]:
    """Speed steps 0 -> 157.08 -> 314.16 rad/s with speed source `source`; figures vs truth."""
    import numpy as np

    from hil.session.closed_loop import ClosedLoop

    t_step = 50e-6
    n = int(round(seconds_per_step / t_step))
    parts = []
    with ClosedLoop() as loop:          # the bench's own closed loop: session + stub + plant
        for ref in (157.08, 314.16):
            loop.command(source, ref)
            parts.append(loop.run(seconds_per_step))
    r = {name: np.concatenate([p[name] for p in parts]) for name in parts[0]}
    w = r["speed_rad_s"]
    out: dict[str, float] = {}
    for k, ref in enumerate((157.08, 314.16)):
        seg = slice(k * n, (k + 1) * n)
        start = 0.0 if k == 0 else 157.08
        ws = w[seg]
        outside = np.nonzero(np.abs(ws - ref) > 0.02 * (ref - start))[0]
        rpm = int(round(ref * 60 / (2 * np.pi), -1))
        out[f"overshoot_pct_to_{rpm}rpm"] = round(float(100 * (ws.max() - ref) / (ref - start)), 2)
        out[f"settling_2pct_s_to_{rpm}rpm"] = round(float((outside[-1] + 1) * t_step) if len(outside) else 0.0, 4)
        tail = slice((k + 1) * n - n // 3, (k + 1) * n)  # last third of each step: steady state
        wt = w[tail]
        out[f"speed_error_mean_rad_s_at_{rpm}rpm"] = round(float(np.mean(wt) - ref), 3)
        for name in ("ekf", "lpf", "encoder"):
            est = r[f"tm_speed_{name}_rad_s"][tail]
            out[f"{name}_speed_rms_error_rad_s_at_{rpm}rpm"] = round(float(np.sqrt(np.mean((est - wt) ** 2))), 3)
        th = r["theta_e_rad"][tail]
        for field, name in (("tm_rotor_pos_conv_rad", "conv"), ("tm_rotor_pos_ekf_rad", "ekf")):
            err = (r[field][tail] - th + np.pi) % (2 * np.pi) - np.pi
            out[f"rotor_pos_{name}_rms_error_rad_at_{rpm}rpm"] = round(float(np.sqrt(np.mean(err**2))), 5)
        psi_est = r["tm_flux_mag_wb"][tail] * np.exp(1j * r["tm_flux_angle_rad"][tail])
        psi = r["psi_alpha"][tail] + 1j * r["psi_beta"][tail]
        out[f"flux_error_max_wb_at_{rpm}rpm"] = float(f"{np.max(np.abs(psi_est - psi)):.3g}")
        out[f"torque_ripple_pp_nm_at_{rpm}rpm"] = round(float(np.ptp(r["torque_nm"][tail])), 3)
    return out


def run(quick: bool = False) -> dict:
    for tool in ("valgrind", "arm-none-eabi-gcc", "arm-none-eabi-size"):
        if shutil.which(tool) is None:
            raise RuntimeError(f"bench stub needs {tool} (scripts/bootstrap.sh installs it)")
    subprocess.run(["make", "-s", "-C", str(STUB), "bench", "arm"], check=True, capture_output=True)
    steps = 500 if quick else 4000
    per_mode = {}
    for name, mode in MODES.items():
        every = instructions_per_step(mode, steps, 1)
        never = instructions_per_step(mode, steps, 0)
        at_divider = instructions_per_step(mode, steps, DEFAULT_TELEMETRY_DIVIDER)
        per_mode[name] = {"with_telemetry": every, "without_telemetry": never,
                          f"telemetry_every_{DEFAULT_TELEMETRY_DIVIDER}": at_divider}
    # the FOC law (step_driver MODE 3: encoder speed and angle), beside the DTC modes
    per_mode["foc_encoder"] = {
        "with_telemetry": instructions_per_step(3, steps, 1),
        "without_telemetry": instructions_per_step(3, steps, 0),
        f"telemetry_every_{DEFAULT_TELEMETRY_DIVIDER}": instructions_per_step(3, steps, DEFAULT_TELEMETRY_DIVIDER)}
    return {
        "instructions_per_control_step_x86_64": per_mode,
        "steps_counted": steps,
        "driver": "firmware_stub/bench/step_driver.c: 150 rad/s rotor, 8 A rotating current, 70 V, running",
        "compiler": subprocess.run([str(DRIVER).replace("step_driver", "hil-stub"), "--version"],
                                   capture_output=True, text=True).stdout.strip(),
        "cortex_m4f_size_bytes": arm_sizes(),
        "closed_loop": {name: closed_loop(mode, 0.15 if quick else 0.3) for name, mode in MODES.items()},
    }
