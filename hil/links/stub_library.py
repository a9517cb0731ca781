"""The in-repo controller stub loaded in-process (link string ``stub``).

The firmware's application layer (codec + control core, the same C code that
runs as ``hil-stub`` and on the Cortex-M4F port) is built as a shared library
with the public firmware ABI (protocol/c/hil_fw_abi.h): bytes received in, bytes
to send out. Each control period costs one ctypes call, and every protocol byte
still goes through the C codec, so the wire format is exercised without an
inter-process hop. ``load_library`` gives the stub's own hil_stub_* calls (tests).
"""
from __future__ import annotations

import ctypes
import threading
from pathlib import Path

from hil.links.firmware_library import FirmwareLibraryLink

REPO_ROOT = Path(__file__).resolve().parents[2]
STUB_DIR = REPO_ROOT / "firmware_stub"
LIBRARY_PATH = STUB_DIR / "build" / "libhilstub.so"
EXECUTABLE_PATH = STUB_DIR / "build" / "hil-stub"

_build_lock = threading.Lock()


class StubBuildError(RuntimeError):
    pass


def ensure_built() -> None:
    """Builds firmware_stub (host executable and shared library) when missing."""
    with _build_lock:
        if LIBRARY_PATH.exists() and EXECUTABLE_PATH.exists():
            return
        import subprocess      # only to build: a run with the stub built needs no subprocess

        proc = subprocess.run(["make", "-s", "-C", str(STUB_DIR)], capture_output=True, text=True)
        if proc.returncode != 0 or not LIBRARY_PATH.exists():
            raise StubBuildError(
                f"building the stub with 'make -C {STUB_DIR}' failed:\n{proc.stdout}{proc.stderr}")


def load_library() -> ctypes.CDLL:
    ensure_built()
    lib = ctypes.CDLL(str(LIBRARY_PATH))
    lib.hil_stub_instance_size.restype = ctypes.c_size_t
    lib.hil_stub_instance_size.argtypes = []
    lib.hil_stub_init.restype = None
    lib.hil_stub_init.argtypes = [ctypes.c_void_p]
    lib.hil_stub_exchange.restype = ctypes.c_size_t
    lib.hil_stub_exchange.argtypes = [ctypes.c_void_p, ctypes.c_char_p, ctypes.c_size_t,
                                      ctypes.c_void_p, ctypes.c_size_t]
    lib.hil_stub_shutdown_requested.restype = ctypes.c_int
    lib.hil_stub_shutdown_requested.argtypes = [ctypes.c_void_p]
    return lib


class StubLibraryLink(FirmwareLibraryLink):
    """The stub firmware in this process (link string ``stub``): ``lib:`` on libhilstub.so,
    through the same public firmware ABI as any user's library (protocol/c/hil_fw_abi.h).
    Its state lives in the instance memory the bench owns, so every session shares the
    process's one load of the library (no private copy, unlike ``lib:``)."""

    def __init__(self, transport: str = "serial") -> None:
        ensure_built()
        super().__init__(LIBRARY_PATH, transport=transport, url="stub", private=False)

    @property
    def _instance(self):
        """The app instance (the ABI's handle is the hil_stub instance): for hil_stub_* calls."""
        return self._fw
