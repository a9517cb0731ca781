"""A firmware built as a shared library, loaded in-process (link string ``lib:PATH.so``).

The library exports the firmware ABI of ``protocol/c/hil_fw_abi.h`` (version 1): create an
instance in memory the bench owns, exchange wire bytes (or CAN frames) in and out, ask whether
SHUTDOWN was received, destroy. The bench refuses a library whose ``hil_fw_abi_version()`` is
not the one it knows, or that lacks a required symbol, naming the file, both versions or the
symbol. Every protocol byte still crosses the firmware's own codec; ``send`` hands the frame to
the firmware at once and whatever it answers is queued for ``recv``, which never waits.

``lib:PATH.so?transport=can`` uses the optional ``hil_fw_can_exchange`` (SPEC.md section 7).
``lib:PATH.so?args=...`` hands the firmware an argument vector (split like ``exec:``'s, by the
registry) through the optional ``hil_fw_configure``; a library without it is refused when given
arguments.

Fresh globals per session. Firmware written for a microcontroller keeps its state in static
variables (an Arduino sketch, most C firmware), and a shared library loaded once per process
would carry that state from one session to the next (the second profile of one ``hil run``),
or refuse a second ``hil_fw_create``. So every session loads its own private copy of the
library: its bytes are copied into an anonymous in-memory file (``memfd_create``) and that file
is dlopen'ed (RTLD_LOCAL) as ``/proc/self/fd/N``. The dynamic loader sees a new file (another
inode, another name) and maps it afresh: new .data, zeroed .bss, constructors run again. The
descriptor stays open while the copy is loaded, because the loader takes a library whose
name is already loaded for that one, and descriptor numbers are reused (a name still loaded
is never used: the copy then goes to a temporary file, below). On close the copy is
dlclose'd and the descriptor closed; the anonymous file has no name on disk, so nothing is
left behind even when the process is killed. Measured on the 2-core box
(200 loads each, the example and stub libraries of 87-184 kB): memfd copy + dlopen + dlclose
0.4-1.0 ms, a copy in a temporary directory 3.6 ms (and a file to clean up after a crash),
the shared load 0.01-0.03 ms. ``dlmopen(LM_ID_NEWLM)`` was the other candidate: it also loads
the C library into each namespace and glibc refuses the 16th namespace, which one ``hil sweep``
worker would reach. Where ``memfd_create`` is missing or a system refuses to map an
anonymous file executable, the copy goes to a private temporary directory instead, which is
removed right after dlopen (the mapping keeps the bytes).

The stub (link ``stub``, hil/links/stub_library.py) keeps all its state in the instance memory
the bench owns (its .data and .bss are the C runtime's 8 bytes each), so it is loaded once per
process and shared: no copy on its start-up path.
"""
from __future__ import annotations

import ctypes
import os
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
# hil_fw_configure's room for the firmware's reason when it refuses its arguments.
_WHY_CAPACITY = 256
_MAX_ARGS = 64
_MAX_ARGS_BYTES = 4096

class FwCanFrame(ctypes.Structure):
    """hil_fw_can_frame: id u16 at 0, dlc u8 at 2, data[8] at 3, size 12."""

    _fields_ = [("id", ctypes.c_uint16), ("dlc", ctypes.c_uint8), ("data", ctypes.c_uint8 * 8)]


assert ctypes.sizeof(FwCanFrame) == 12


class FirmwareImage:
    """One loaded copy of a firmware library: the checked ctypes handle and how to unload it.

    ``private``: a copy of its own (fresh globals, see the module's docstring), unloaded by
    ``release``; otherwise the process's one shared load, which ``release`` leaves loaded."""

    def __init__(self, path: Path, lib: ctypes.CDLL, private: bool, fd: int | None = None) -> None:
        self.path, self.lib, self.private = path, lib, private
        self._fd = fd
        self._loaded = True

    def release(self) -> None:
        """Unloads a private copy (once); a shared load stays. No call into it may follow."""
        if not (self.private and self._loaded):
            return
        self._loaded = False
        name = self.lib._name
        _dlclose(self.lib._handle)
        if self._fd is not None:
            if _still_loaded(name):
                # The loader kept it (a library marked NODELETE): keep its descriptor too, so
                # that no later copy gets the same /proc/self/fd/N name and with it this one.
                _PINNED_FDS.append(self._fd)
            else:
                os.close(self._fd)
            self._fd = None


# Descriptors of private copies the loader would not unload (see FirmwareImage.release).
_PINNED_FDS: list[int] = []
# path -> the one shared load of a library (the stub's).
_SHARED: dict[Path, ctypes.CDLL] = {}


def _dlclose(handle: int) -> None:
    import _ctypes

    _ctypes.dlclose(handle)


def _still_loaded(name: str) -> bool:
    """True when a library of this exact name is loaded in the process (RTLD_NOLOAD)."""
    try:
        probe = ctypes.CDLL(name, mode=os.RTLD_NOLOAD | os.RTLD_LAZY)
    except OSError:
        return False
    _dlclose(probe._handle)            # the probe took a reference of its own
    return True


def _memfd_copy(data: bytes, where: str) -> tuple[ctypes.CDLL, int] | None:
    """dlopen of an anonymous in-memory copy; None where memfd is missing or refused."""
    if not hasattr(os, "memfd_create"):
        return None
    try:
        fd = os.memfd_create("hil-fw", os.MFD_CLOEXEC)
    except OSError:
        return None
    try:
        view = memoryview(data)
        while view:
            view = view[os.write(fd, view):]
        name = f"/proc/self/fd/{fd}"
        if _still_loaded(name):
            os.close(fd)
            return None
        try:
            return ctypes.CDLL(name, mode=os.RTLD_LOCAL | os.RTLD_NOW), fd
        except OSError as exc:
            if "failed to map segment" in str(exc) or "Permission denied" in str(exc):
                os.close(fd)       # memfd not executable here (vm.memfd_noexec): use a file
                return None
            raise LinkError(f"{where}: cannot load: {exc}") from exc
    except BaseException:
        try:
            os.close(fd)
        except OSError:
            pass
        raise


def _tempfile_copy(path: Path, where: str) -> ctypes.CDLL:
    """dlopen of a copy in a private temporary directory, removed at once after loading."""
    # imported here: the memfd path (every Linux since 3.17) needs neither, and shutil brings
    # bz2 and lzma into every `hil run` start-up
    import shutil
    import tempfile

    tmp = tempfile.mkdtemp(prefix="hil-fw-")
    try:
        copy = Path(tmp) / path.name
        shutil.copyfile(path, copy)
        try:
            return ctypes.CDLL(str(copy), mode=os.RTLD_LOCAL | os.RTLD_NOW)
        except OSError as exc:
            raise LinkError(f"{where}: cannot load: {exc}") from exc
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def load_firmware_library(path: str | Path, private: bool = True) -> FirmwareImage:
    """Loads and checks a firmware library; LinkError names the file and what is wrong.

    ``private``: a copy of its own with fresh globals (every ``lib:`` session); otherwise
    the process's one shared load (the stub's)."""
    path = Path(path)
    where = f"firmware library '{path}'"
    if not path.exists():
        raise LinkError(f"{where}: no such file")
    fd = None
    try:
        if not private:
            key = path.resolve()
            lib = _SHARED.get(key) or ctypes.CDLL(str(key))
        else:
            try:
                data = path.read_bytes()
            except OSError as exc:
                raise LinkError(f"{where}: cannot read: {exc.strerror}") from exc
            loaded = _memfd_copy(data, where)
            lib, fd = loaded if loaded is not None else (_tempfile_copy(path, where), None)
    except OSError as exc:
        raise LinkError(f"{where}: cannot load: {exc}") from exc
    image = FirmwareImage(path, lib, private, fd)
    try:
        _check_and_declare(lib, where)
    except BaseException:
        image.release()
        raise
    if not private:
        _SHARED[path.resolve()] = lib
    return image


def _check_and_declare(lib: ctypes.CDLL, where: str) -> None:
    """Refuses a library without the required symbols or of another ABI version; declares
    the signatures of the calls it has."""
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
    if hasattr(lib, "hil_fw_configure"):
        lib.hil_fw_configure.restype = ctypes.c_int
        lib.hil_fw_configure.argtypes = [ctypes.c_void_p, ctypes.c_int, ctypes.POINTER(ctypes.c_char_p),
                                         ctypes.c_char_p, ctypes.c_size_t]


def _check_args(args: list[str], where: str) -> list[bytes]:
    """The argument vector as C strings: no NUL inside, bounded in count and bytes."""
    if len(args) > _MAX_ARGS:
        raise LinkError(f"{where}: {len(args)} arguments; at most {_MAX_ARGS}")
    encoded = [a.encode("utf-8") for a in args]
    for arg, raw in zip(args, encoded):
        if b"\0" in raw:
            raise LinkError(f"{where}: argument {arg!r} contains a NUL byte")
    if sum(len(r) + 1 for r in encoded) > _MAX_ARGS_BYTES:
        raise LinkError(f"{where}: arguments longer than {_MAX_ARGS_BYTES} bytes")
    return encoded


class _FirmwareLibrary(Link):
    """A Link whose far end is a firmware library in this process (serial or CAN transport)."""

    def __init__(self, path: str | Path, transport: str = "serial", url: str | None = None,
                 args: list[str] | None = None, private: bool = True) -> None:
        where = f"firmware library '{path}'"
        if transport not in ("serial", "can"):
            raise LinkError(f"{where}: transport '{transport}'; expected serial or can")
        self.path = Path(path)
        self.url = url or f"lib:{path}"
        self._closed = True           # until the instance exists: close() has nothing to end
        self._fw = None
        self._image = load_firmware_library(path, private=private)
        try:
            self._create(where, transport, args or [])
        except BaseException:
            self._image.release()
            raise

    def _create(self, where: str, transport: str, args: list[str]) -> None:
        self._lib = lib = self._image.lib
        self.name = (lib.hil_fw_name() or b"").decode("utf-8", "replace")
        if transport == "can" and not hasattr(lib, "hil_fw_can_exchange"):
            raise LinkError(f"{where}: transport=can needs hil_fw_can_exchange, "
                            "which it does not export (it speaks serial only)")
        configure = getattr(lib, "hil_fw_configure", None)
        if args and configure is None:
            raise LinkError(f"{where}: given args {' '.join(args)!r}, but it does not export "
                            "hil_fw_configure, the optional ABI call that takes them "
                            "(protocol/c/hil_fw_abi.h)")
        argv = _check_args(args, where)
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
            raise LinkError(f"{where}: hil_fw_create returned NULL (the memory the bench gave: "
                            f"{size} bytes aligned to {INSTANCE_ALIGN}; every session has its "
                            "own copy of the library, so this is not another session's instance)")
        if configure is not None:
            self._configure(configure, argv, where)
        self._init_link_state()

    def _configure(self, configure, argv: list[bytes], where: str) -> None:
        """Hands the firmware its argument vector (argv[argc] is NULL, as for main)."""
        c_argv = (ctypes.c_char_p * (len(argv) + 1))(*argv, None)
        why = ctypes.create_string_buffer(_WHY_CAPACITY)
        status = configure(self._fw, len(argv), c_argv, why, _WHY_CAPACITY)
        if status != 0:
            self._lib.hil_fw_destroy(self._fw)
            self._fw = None
            reason = why.value.decode("utf-8", "replace").strip() or "no reason given"
            given = " ".join(a.decode("utf-8", "replace") for a in argv) or "(none)"
            raise LinkError(f"{where}: hil_fw_configure refused args {given!r} "
                            f"(status {status}): {reason}")

    def _init_link_state(self) -> None:
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
            try:
                self._lib.hil_fw_destroy(self._fw)
            finally:
                self._fw = None
                self._image.release()     # a private copy is unloaded: no call after this


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

    def __init__(self, path: str | Path, url: str | None = None, args: list[str] | None = None) -> None:
        super().__init__(path, transport="can", url=url, args=args)


def open_firmware_library(path: str | Path, transport: str = "serial", url: str | None = None,
                          args: list[str] | None = None):
    """A link to a private copy of the library at ``path`` (fresh globals), its instance
    created and, when ``args`` are given or the library exports hil_fw_configure, configured."""
    if transport == "can":
        return FirmwareLibraryCanLink(path, url=url, args=args)
    return FirmwareLibraryLink(path, transport=transport, url=url, args=args)
