"""Keeps the CPUs out of deep idle states while a session waits on another process.

Linux's PM QoS interface: while a process holds /dev/cpu_dma_latency open with a
value written to it, no CPU enters an idle state whose exit latency exceeds that
value (what cyclictest does). A bench waiting microseconds for a board's answer
over a pseudo-terminal, a serial adapter or QEMU otherwise pays, every period,
for both sides waking from deep idle with cold caches: measured on this 2-core
VM, a pty round trip with the C echo goes from about 70 us to about 20-30 us
held at 0, and the bench's own Python work after each wake-up from about 20 us
to about 15 us (it runs 2-3 times slower straight out of a sleep). The price is
power: the CPUs spin in shallow idle states while the hold lasts.

Needs write access to the device (root, or a udev rule); without it the hold
records why and the session runs as before, only slower.
"""
from __future__ import annotations

import os
import struct


class CpuLatencyHold:
    """Holds /dev/cpu_dma_latency at ``latency_us`` while open (where the OS permits)."""

    PATH = "/dev/cpu_dma_latency"

    def __init__(self, latency_us: int = 0) -> None:
        self.latency_us = latency_us
        self.fd: int | None = None
        self.status = "not requested"

    def __enter__(self) -> "CpuLatencyHold":
        self.acquire()
        return self

    def __exit__(self, *exc) -> None:
        self.release()

    def acquire(self) -> str:
        if self.fd is None:
            try:
                fd = os.open(self.PATH, os.O_WRONLY)
                try:
                    os.write(fd, struct.pack("<i", self.latency_us))
                except OSError:
                    os.close(fd)
                    raise
            except OSError as exc:
                self.status = f"not available ({self.PATH}: {exc.strerror})"
                return self.status
            self.fd = fd
            self.status = f"held at {self.latency_us} us"
        return self.status

    def release(self) -> None:
        """The kernel drops the request when the descriptor closes."""
        if self.fd is not None:
            os.close(self.fd)
            self.fd = None
