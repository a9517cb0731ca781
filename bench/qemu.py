"""The control step on the Cortex-M4F target: cycles per ctl_step as the firmware itself
measures them with SysTick under QEMU's -icount (deterministic: one instruction per count),
per speed source, and the firmware's flash and RAM. `hil bench` prints it beside the host
figure of bench/stub.py (x86-64 instructions counted with callgrind)."""
from __future__ import annotations

from hil.links.qemu import measure_control_step


def run(quick: bool = False) -> dict:
    return measure_control_step(samples=100 if quick else 400)
