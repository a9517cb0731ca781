"""A firmware built as a shared library, loaded in-process (link string ``lib:PATH.so``).

The library exports the firmware ABI of ``protocol/c/hil_fw_abi.h`` (version 1): create an
instance in memory the bench owns, exchange wire bytes (or CAN frames) in and out, ask whether
SHUTDOWN was received, destroy. The bench refuses a library whose ``hil_fw_abi_version()`` is
not the one it knows, or that lacks a required symbol, naming the file, both versions or the
symbol. Every protocol byte still crosses the firmware's own codec; ``send`` hands the frame to
the firmware at once and whatever it answers is queued for ``recv``, which never waits.

``lib:PATH.so?transport=can`` uses the optional ``hil_fw_can_exchange`` (SPEC.md section 7).
"""
from __future__ import annotations

import ctypes
from array import array
from collections import deque
from functools import partial
from pathlib import Path

from protocol.can_mapping import DEFAULT_BASE_ID, CanReassembler, can_pack
from protocol.codec import FrameEncoder, StreamDecoder
from protocol.links import Link, LinkError
from protocol.messages import Role

#: HIL_FW_ABI_VERSION of protocol/c/hil_fw_abi.h as this bench knows it.
ABI_VERSION = 1
INSTANCE_ALIGN = 16
REQUIRED_SYMBOLS = ("hil_fw_abi_version", "hil_fw_name", "hil_fw_instance_size", "hil_fw_create",
                    "hil_fw_exchange", "hil_fw_shutdown_requested", "hil_fw_destroy")
# Largest answer to one call: GATES + TELEMETRY + a FAULT/STATUS/PARAM_VALUE or two.
_TX_CAPACITY = 4096
_CAN_TX_CAPACITY = 64


class FwCanFrame(ctypes.Structure):
    """hil_fw_can_frame: id u16 at 0, dlc u8 at 2, data[8] at 3, size 12."""

    _fields_ = [("id", ctypes.c_uint16), ("dlc", ctypes.c_uint8), ("data", ctypes.c_uint8 * 8)]


assert ctypes.sizeof(FwCanFrame) == 12


def load_firmware_library(path: str | Path) -> ctypes.CDLL:
    """Loads and checks a firmware library; LinkError names the file and what is wrong."""
    path = Path(path)
    where = f"firmware library '{path}'"
    if not path.exists():
        raise LinkError(f"{where}: no such file")
    try:
        lib = ctypes.CDLL(str(path.resolve()))
    except OSError as exc:
        raise LinkError(f"{where}: cannot load: {exc}") from exc
    missing = [name for name in REQUIRED_SYMBOLS if not hasattr(lib, name)]
    if missing:
        raise LinkError(f"{where}: does not export {', '.join(missing)} (the firmware ABI of "
                        f"protocol/c/hil_fw_abi.h; docs/porting.md)")
    lib.hil_fw_abi_version.restype = ctypes.c_uint32
    lib.hil_fw_abi_version.argtypes = []
    version = lib.hil_fw_abi_version()
    if version != ABI_VERSION:
        raise LinkError(f"{where}: firmware ABI version {version}, the bench speaks version "
                        f"{ABI_VERSION} (protocol/c/hil_fw_abi.h)")
    lib.hil_fw_name.restype = ctypes.c_char_p
    lib.hil_fw_name.argtypes = []
    lib.hil_fw_instance_size.restype = ctypes.c_size_t
    lib.hil_fw_instance_size.argtypes = []
    lib.hil_fw_create.restype = ctypes.c_void_p
    lib.hil_fw_create.argtypes = [ctypes.c_void_p, ctypes.c_size_t]
    lib.hil_fw_exchange.restype = ctypes.c_size_t
    lib.hil_fw_exchange.argtypes = [ctypes.c_void_p, ctypes.c_char_p, ctypes.c_size_t,
                                    ctypes.c_void_p, ctypes.c_size_t]
    lib.hil_fw_shutdown_requested.restype = ctypes.c_int
    lib.hil_fw_shutdown_requested.argtypes = [ctypes.c_void_p]
    lib.hil_fw_destroy.restype = None
    lib.hil_fw_destroy.argtypes = [ctypes.c_void_p]
    if hasattr(lib, "hil_fw_can_exchange"):
        lib.hil_fw_can_exchange.restype = ctypes.c_size_t
        lib.hil_fw_can_exchange.argtypes = [ctypes.c_void_p, ctypes.POINTER(FwCanFrame), ctypes.c_size_t,
                                            ctypes.POINTER(FwCanFrame), ctypes.c_size_t]
    return lib


class _FirmwareLibrary(Link):
    """A Link whose far end is a firmware library in this process (serial or CAN transport)."""

    def __init__(self, path: str | Path, transport: str = "serial", url: str | None = None) -> None:
        if transport not in ("serial", "can"):
            raise LinkError(f"firmware library '{path}': transport '{transport}'; expected serial or can")
        self.path = Path(path)
        self.url = url or f"lib:{path}"
        self._lib = lib = load_firmware_library(path)
        self.name = (lib.hil_fw_name() or b"").decode("utf-8", "replace")
        if transport == "can" and not hasattr(lib, "hil_fw_can_exchange"):
            raise LinkError(f"firmware library '{path}': transport=can needs hil_fw_can_exchange, "
                            "which it does not export (it speaks serial only)")
        self.transport = transport
        size = lib.hil_fw_instance_size()
        # Over-allocate and align by hand: the ABI asks for HIL_FW_INSTANCE_ALIGN.
        self._memory = ctypes.create_string_buffer(size + INSTANCE_ALIGN) if size else None
        mem = None
        if self._memory is not None:
            base = ctypes.addressof(self._memory)
            mem = base + (-base) % INSTANCE_ALIGN
        self._fw = lib.hil_fw_create(mem, size)
        if not self._fw:
            raise LinkError(f"firmware library '{path}': hil_fw_create returned NULL (a firmware "
                            "with static state supports one instance per process; is another "
                            "session using it?)")
        self._tx = ctypes.create_string_buffer(_TX_CAPACITY)
        self._can_tx = (FwCanFrame * _CAN_TX_CAPACITY)()
        self._encoder = FrameEncoder()
        self._decoder = StreamDecoder()
        self._reassembler = CanReassembler(DEFAULT_BASE_ID)
        self._can_seq = 0
        self._inbox: deque = deque()
        self._raw = bytearray()       # answers not yet decoded (read_bytes takes them raw)
        self._closed = False
        self.tx_bytes = self.rx_bytes = self.tx_frames = self.rx_frames = 0
        # What the C period exchange did (sample_exchange): frames out, frames in, bytes out,
        # bytes in, and a closed flag it checks before each call (the instance is freed on close)
        self.exchange_counts = array("q", [0] * 5)

    # -- serial
    def send(self, msg) -> None:
        if self.transport == "can":
            self._send_can(msg)
            return
        self._send_bytes(self._encoder.encode(msg))

    def _send_bytes(self, data: bytes) -> None:
        """Feeds raw bytes to the firmware (fault injection sends damaged frames this way)."""
        self._check_open()
        if self.transport == "can":
            raise LinkError(f"{self.url}: send_bytes needs the serial transport")
        lib, fw, tx = self._lib, self._fw, self._tx
        n = lib.hil_fw_exchange(fw, data, len(data), tx, _TX_CAPACITY)
        self.tx_bytes += len(data)
        self.tx_frames += data.count(0)
        while n:
            self._raw += tx.raw[:n]
            self.rx_bytes += n
            if n < _TX_CAPACITY:
                break
            n = lib.hil_fw_exchange(fw, None, 0, tx, _TX_CAPACITY)   # drain what did not fit

    def recv(self, timeout_s: float | None = 0.0):
        inbox = self._inbox
        if not inbox and self._raw:
            inbox.extend(self._decoder.feed(bytes(self._raw)))
            self._raw.clear()
        if not inbox and self._closed:
            raise LinkError(f"{self.url}: link is closed")
        return inbox.popleft() if inbox else None

    def _read_bytes(self, timeout_s: float | None = 0.0) -> bytes:
        """The firmware's answers as raw bytes, bypassing the decoder (link taps)."""
        self._check_open()
        data = bytes(self._raw)
        self._raw.clear()
        return data

    # -- CAN
    def _send_can(self, msg) -> None:
        self._check_open()
        frames = can_pack(msg, Role.BENCH, DEFAULT_BASE_ID, self._can_seq)
        if len(frames) > 1:
            self._can_seq = (self._can_seq + 1) & 0x0F
        rx = (FwCanFrame * len(frames))()
        for slot, (ident, data) in zip(rx, frames):
            slot.id, slot.dlc = ident, len(data)
            for i, b in enumerate(data):
                slot.data[i] = b
        self.tx_frames += len(frames)
        count, first = len(frames), rx
        while True:
            n = self._lib.hil_fw_can_exchange(self._fw, first, count, self._can_tx, _CAN_TX_CAPACITY)
            for f in self._can_tx[:n]:
                self.rx_frames += 1
                got = self._reassembler.feed(f.id, bytes(f.data[: f.dlc]))
                if got is not None:
                    self._inbox.append(got[0])
            if n < _CAN_TX_CAPACITY:
                break
            count, first = 0, None

    def shutdown_requested(self) -> bool:
        return not self._closed and bool(self._lib.hil_fw_shutdown_requested(self._fw))

    def _check_open(self) -> None:
        if self._closed:
            raise LinkError(f"{self.url}: link is closed")

    @property
    def counters(self) -> dict[str, int]:
        if self.transport == "can":
            c = dict(self._reassembler.counters)
            c.update(tx_frames=self.tx_frames, rx_frames=self.rx_frames)
            return c
        c = dict(self._decoder.counters)
        x = self.exchange_counts
        c.update(tx_frames=self.tx_frames + x[0], tx_bytes=self.tx_bytes + x[2],
                 rx_bytes=self.rx_bytes + x[3])
        return c

    @property
    def decoder(self) -> StreamDecoder:
        return self._decoder

    def close(self) -> None:
        if not self._closed:
            self._closed = True
            self.exchange_counts[4] = 1
            self._lib.hil_fw_destroy(self._fw)
            self._fw = None


class FirmwareLibraryLink(_FirmwareLibrary):
    """The serial transport: also raw bytes in and out, so a link tap (raw-frame log, link
    faults) can sit in front of it."""

    send_bytes = _FirmwareLibrary._send_bytes
    read_bytes = _FirmwareLibrary._read_bytes

    def exchange_target(self) -> tuple[int, int] | None:
        """(address of hil_fw_exchange, instance) for a caller that drives the firmware from C
        (protocol.ccodec's exchange_sample), or None once closed."""
        if self._closed:
            return None
        return ctypes.cast(self._lib.hil_fw_exchange, ctypes.c_void_p).value, self._fw

    def sample_exchange(self, exchange_sample, encoder, decoder, cap_out: bytearray,
                        cap_in: bytearray, inbox):
        """A function (k, adc_i1, adc_i2, adc_vdc, encoder, status) for a link tap that drives
        this firmware from C (protocol.ccodec's `exchange_sample`, bound to this firmware and
        the tap's codec, captures and inbox; a functools.partial, so no Python frame a
        period): one C call sends SAMPLE(k), appends both directions' frames to the captures,
        counts them in `exchange_counts` and queues the answers in `inbox`. Only while
        `exchange_ready` (answers to earlier frames are still in the link's buffer otherwise);
        once the link is closed the call raises ValueError instead of reaching the freed
        instance. The per-period path of every in-process lockstep run."""
        fn, fw = self.exchange_target()
        return partial(exchange_sample, fn, fw, encoder, decoder, cap_out, cap_in,
                       self.exchange_counts, inbox)

    @property
    def exchange_ready(self) -> bool:
        """Open, and no answer to an earlier frame waiting to be read (they come first)."""
        return not self._closed and not self._raw


class FirmwareLibraryCanLink(_FirmwareLibrary):
    """The CAN transport (hil_fw_can_exchange): frames, not bytes; not tapped."""

    def __init__(self, path: str | Path, url: str | None = None) -> None:
        super().__init__(path, transport="can", url=url)


def open_firmware_library(path: str | Path, transport: str = "serial", url: str | None = None):
    if transport == "can":
        return FirmwareLibraryCanLink(path, url=url)
    return FirmwareLibraryLink(path, transport=transport, url=url)
