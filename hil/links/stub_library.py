"""The in-repo controller stub loaded in-process (link string ``stub``).

The firmware's application layer (codec + control core, the same C code that
runs as ``hil-stub`` and on the Cortex-M4F port) is built as a shared library
with a byte interface: bytes received in, bytes to send out. Each control
period costs one ctypes call, and every protocol byte still goes through the
C codec, so the wire format is exercised without an inter-process hop.
"""
from __future__ import annotations

import ctypes
import subprocess
import threading
from collections import deque
from pathlib import Path

from protocol.codec import FrameEncoder, StreamDecoder

REPO_ROOT = Path(__file__).resolve().parents[2]
STUB_DIR = REPO_ROOT / "firmware_stub"
LIBRARY_PATH = STUB_DIR / "build" / "libhilstub.so"
EXECUTABLE_PATH = STUB_DIR / "build" / "hil-stub"

# Largest answer to one call: GATES + TELEMETRY + a FAULT/STATUS/PARAM_VALUE or two.
_TX_CAPACITY = 4096

_build_lock = threading.Lock()


class StubBuildError(RuntimeError):
    pass


def ensure_built() -> None:
    """Builds firmware_stub (host executable and shared library) when missing."""
    with _build_lock:
        if LIBRARY_PATH.exists() and EXECUTABLE_PATH.exists():
            return
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


class StubLibraryLink:
    """A link whose far end is the stub firmware running inside this process.

    Same interface as protocol.links.Link: send, recv, close, counters.
    ``send`` hands the encoded frame to the firmware at once; whatever it
    answers is decoded and queued for ``recv``, so ``recv`` never waits.
    """

    url = "stub"

    def __init__(self) -> None:
        self._lib = load_library()
        size = self._lib.hil_stub_instance_size()
        self._instance = ctypes.create_string_buffer(size)
        self._lib.hil_stub_init(self._instance)
        self._tx = ctypes.create_string_buffer(_TX_CAPACITY)
        self._encoder = FrameEncoder()
        self._decoder = StreamDecoder()
        self._inbox: deque = deque()
        self._raw = bytearray()       # answers not yet decoded (read_bytes takes them raw)
        self._closed = False
        self.bytes_out = 0
        self.bytes_in = 0
        self.frames_out = 0

    def send(self, msg) -> None:
        self.send_bytes(self._encoder.encode(msg))

    def send_bytes(self, data: bytes) -> None:
        """Feeds raw bytes to the firmware (also used by fault injection to send damaged frames)."""
        if self._closed:
            raise ConnectionError("stub link is closed")
        n = self._lib.hil_stub_exchange(self._instance, data, len(data), self._tx, _TX_CAPACITY)
        self.bytes_out += len(data)
        self.frames_out += 1
        if n:
            self._raw += self._tx.raw[:n]
            self.bytes_in += n

    def recv(self, timeout_s: float | None = None):
        inbox = self._inbox
        if not inbox and self._raw:
            inbox.extend(self._decoder.feed(bytes(self._raw)))
            self._raw.clear()
        return inbox.popleft() if inbox else None

    def read_bytes(self, timeout_s: float | None = None) -> bytes:
        """The firmware's answers as raw bytes, bypassing the decoder (link taps)."""
        data = bytes(self._raw)
        self._raw.clear()
        return data

    def shutdown_requested(self) -> bool:
        return bool(self._lib.hil_stub_shutdown_requested(self._instance))

    @property
    def counters(self) -> dict[str, int]:
        counters = dict(self._decoder.counters)
        counters.update(bytes_out=self.bytes_out, bytes_in=self.bytes_in, frames_out=self.frames_out)
        return counters

    def close(self) -> None:
        self._closed = True

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()
