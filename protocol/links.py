"""Links: one small interface over serial ports, CAN buses and an in-process pair.

    link = open_link("serial:/dev/ttyUSB0?baud=2000000")      # any pyserial port or URL
    link = open_link("can:socketcan:can0?bitrate=500000", role=Role.BENCH)  # any python-can interface
    a, b = make_pair()                                          # in-process, for tests
    link.send(msg); link.recv(timeout_s) -> message | None; link.counters; link.close()

recv(timeout_s): 0 polls, None waits without limit. Errors opening or using
a link raise LinkError naming the port, interface or channel and the reason.
"""
from __future__ import annotations

import abc
import errno
import os
import select
import threading
import time
from collections import deque
from urllib.parse import parse_qsl, urlencode

from protocol.can_mapping import DEFAULT_BASE_ID, ID_SPAN, ROLE_STRIDE, CanReassembler, can_pack, check_base_id
from protocol.codec import FrameEncoder, ProtocolError, StreamDecoder
from protocol.messages import Role

DEFAULT_BAUD = 115_200
WRITE_TIMEOUT_S = 2.0


class LinkError(ConnectionError):
    """A link that cannot be opened or used; the message names the port or bus and the reason."""


class Link(abc.ABC):
    """Send a message, receive one with a timeout, close, counters. Usable as a context manager."""

    url: str = ""

    @abc.abstractmethod
    def send(self, msg) -> None:
        """Encodes and sends one message; raises LinkError if the link is closed or broken."""

    @abc.abstractmethod
    def recv(self, timeout_s: float | None = 0.0):
        """The next message, or None after timeout_s (0: poll, None: no limit)."""

    @abc.abstractmethod
    def close(self) -> None:
        """Releases the port or bus; idempotent."""

    @property
    @abc.abstractmethod
    def counters(self) -> dict[str, int]:
        """Decoder/reassembler counters plus the link's own traffic counts."""

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.url!r})"


def _deadline(timeout_s: float | None) -> float | None:
    return None if timeout_s is None else time.monotonic() + max(0.0, timeout_s)


def _remaining(deadline: float | None) -> float | None:
    return None if deadline is None else max(0.0, deadline - time.monotonic())


# ---------------------------------------------------------------- serial

class SerialLink(Link):
    """The serial framing over any pyserial port: a device path, a pseudo-terminal, or a URL
    (loop://, socket://host:port, rfc2217://...)."""

    def __init__(self, port: str, baudrate: int = DEFAULT_BAUD, write_timeout_s: float = WRITE_TIMEOUT_S,
                 **serial_kwargs) -> None:
        import serial  # pyserial

        self.url = port
        self._encoder = FrameEncoder()
        self._decoder = StreamDecoder()
        self._inbox: deque = deque()
        self._write_timeout_s = write_timeout_s
        self.tx_frames = self.tx_bytes = self.rx_bytes = 0
        self._open_frame = False
        is_url = "://" in port
        if not is_url:
            serial_kwargs.setdefault("exclusive", True)
        try:
            self._port = serial.serial_for_url(port, baudrate=baudrate, timeout=0,
                                               write_timeout=write_timeout_s, **serial_kwargs)
        except (serial.SerialException, OSError, ValueError) as exc:
            raise LinkError(f"serial port '{port}': cannot open: {_serial_reason(port, exc)}") from exc
        # A real file descriptor (device, pty) is read and written directly: pyserial's
        # read() reconfigures the port whenever its timeout changes.
        try:
            self._fd = self._port.fileno() if not is_url else None
        except Exception:  # noqa: BLE001 - ports without a descriptor use pyserial's read
            self._fd = None
        self._readable = [self._fd]   # select()'s read list, made once
        self._port_timeout = 0.0
        self._closed = False

    # -- sending
    def send(self, msg) -> None:
        data = self._encoder.encode(msg)
        if not self.tx_bytes:
            data = b"\x00" + data  # closes off whatever the far end had buffered (SPEC.md 3.2)
        self.send_bytes(data)

    def send_bytes(self, data: bytes) -> None:
        """Writes raw bytes (fault injection: damaged or partial frames). On a file descriptor
        a frame goes out in one write() call, the per-period path of stub-pty and real boards."""
        if self._closed:
            self._check_open()
        fd = self._fd
        try:
            if fd is not None:
                try:
                    n = os.write(fd, data)
                except BlockingIOError:     # the line's buffer is full: wait for room below
                    n = 0
                if n != len(data):
                    self._write_rest(data, n)
            else:
                self._port.write(data)
        except LinkError:
            raise
        except Exception as exc:  # noqa: BLE001 - pyserial raises SerialException, OSError, ...
            raise LinkError(f"serial port '{self.url}': write failed: {exc}") from exc
        size = len(data)
        self.tx_bytes += size
        # tx_frames counts the non-empty frames written, whoever framed them (send, or a link
        # tap handing whole frames to send_bytes): one per 0x00 that closes a non-empty run.
        if size and data.find(0) == size - 1:      # one whole frame (or a lone delimiter)
            if size > 1 or self._open_frame:
                self.tx_frames += 1
            self._open_frame = False
        elif 0 in data:
            parts = data.split(b"\x00")
            frames = sum(1 for p in parts[1:-1] if p) + (1 if parts[0] or self._open_frame else 0)
            self.tx_frames += frames
            self._open_frame = bool(parts[-1])
        elif data:
            self._open_frame = True

    def _write_rest(self, data: bytes, done: int) -> None:
        """The rest of a write the line did not take at once, within the write timeout."""
        view = memoryview(data)[done:]
        deadline = None
        while view:
            try:
                n = os.write(self._fd, view)
                view = view[n:]
            except BlockingIOError:
                if deadline is None:
                    deadline = time.monotonic() + self._write_timeout_s
                left = deadline - time.monotonic()
                if left <= 0 or not select.select([], [self._fd], [], left)[1]:
                    raise LinkError(f"serial port '{self.url}': write timed out after "
                                    f"{self._write_timeout_s:g} s (nobody reading?)") from None

    # -- receiving
    def recv(self, timeout_s: float | None = 0.0):
        inbox = self._inbox
        if inbox:
            return inbox.popleft()
        self._check_open()
        if timeout_s is not None and timeout_s < 0:
            timeout_s = 0.0
        deadline = None if timeout_s is None else time.monotonic() + timeout_s
        remaining = timeout_s
        while True:
            data = self.read_bytes(remaining)
            if data:
                msgs = self._decoder.feed(data)
                if msgs:
                    inbox.extend(msgs)
                    return inbox.popleft()
            if deadline is not None:
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    return None

    def read_bytes(self, timeout_s: float | None = 0.0) -> bytes:
        """Raw bytes as they arrive, bypassing the decoder (link taps, benchmarks, fault-injection
        tests): what one read() returns once the line is readable, b'' after timeout_s."""
        if self._closed:
            self._check_open()
        fd = self._fd
        if fd is None:
            data = self._read_port(timeout_s)
        else:       # a descriptor (device, pty) read directly: a link tap's per-period call
            if not select.select(self._readable, (), (), timeout_s)[0]:
                return b""
            try:
                data = os.read(fd, 4096)
            except BlockingIOError:
                return b""
            except OSError as exc:
                if exc.errno == errno.EIO:  # the other side of a pseudo-terminal closed
                    raise LinkError(f"serial port '{self.url}': the other end closed the line") from exc
                raise LinkError(f"serial port '{self.url}': read failed: {exc}") from exc
            if not data:
                raise LinkError(f"serial port '{self.url}': the other end closed the line")
        self.rx_bytes += len(data)
        return data

    def _read_port(self, timeout_s: float | None) -> bytes:
        """What pyserial's port has, once something is there or after timeout_s."""
        try:
            if timeout_s != self._port_timeout:
                self._port.timeout = timeout_s
                self._port_timeout = timeout_s
            return self._port.read(max(1, self._port.in_waiting))
        except Exception as exc:  # noqa: BLE001
            raise LinkError(f"serial port '{self.url}': read failed: {exc}") from exc

    def _check_open(self) -> None:
        if self._closed:
            raise LinkError(f"serial port '{self.url}': link is closed")

    @property
    def counters(self) -> dict[str, int]:
        c = self._decoder.counters
        c.update(tx_frames=self.tx_frames, tx_bytes=self.tx_bytes, rx_bytes=self.rx_bytes)
        return c

    # -- for a caller that reads and writes the descriptor itself (the bench's C period loop)
    def descriptor(self) -> int | None:
        """The open line's file descriptor (a device or a pseudo-terminal), None for a URL
        port or once closed."""
        return None if self._closed else self._fd

    @property
    def write_timeout_s(self) -> float:
        return self._write_timeout_s

    def count_direct(self, tx_frames: int, tx_bytes: int, rx_bytes: int) -> None:
        """Adds what such a caller wrote (whole frames) and read to this link's counters."""
        self.tx_frames += tx_frames
        self.tx_bytes += tx_bytes
        self.rx_bytes += rx_bytes

    @property
    def decoder(self) -> StreamDecoder:
        return self._decoder

    def close(self) -> None:
        if not self._closed:
            self._closed = True
            try:
                self._port.close()
            except Exception:  # noqa: BLE001 - closing must not fail
                pass


def _serial_reason(port: str, exc: Exception) -> str:
    text = str(exc)
    if "exclusively lock" in text or "Resource temporarily unavailable" in text:
        return "port is busy (opened by another program)"
    if "No such file or directory" in text or "could not open port" in text and "Errno 2" in text:
        return "no such port"
    if "Permission denied" in text:
        return "permission denied (is the user in the dialout group?)"
    return text


# ---------------------------------------------------------------- CAN

class CanLink(Link):
    """The CAN mapping over any python-can interface (socketcan, slcan, pcan, kvaser, virtual, ...)."""

    def __init__(self, interface: str, channel: str | None, role: int = Role.BENCH,
                 base_id: int = DEFAULT_BASE_ID, bitrate: int | None = None, **bus_kwargs) -> None:
        import can  # python-can

        self.url = f"can:{interface}:{channel or ''}"
        try:
            self.role = int(Role(role))
            self.base_id = check_base_id(base_id)
        except (ValueError, ProtocolError) as exc:
            raise LinkError(f"CAN link {self.url}: {exc}") from exc
        self._reassembler = CanReassembler(base_id)
        self._inbox: deque = deque()
        self._seq = 0
        self.tx_frames = self.rx_frames = self.own_role_frames = 0
        if bitrate is not None:
            bus_kwargs["bitrate"] = bitrate
        where = f"CAN interface '{interface}' channel '{channel}'"
        try:
            self._bus = can.Bus(interface=interface, channel=channel, **bus_kwargs)
        except can.exceptions.CanInterfaceNotImplementedError as exc:
            known = ", ".join(sorted(can.interfaces.VALID_INTERFACES))
            raise LinkError(f"{where}: interface not available ({exc}); python-can knows: {known}") from exc
        except (can.CanError, OSError, ValueError, TypeError, ImportError) as exc:
            raise LinkError(f"{where}: cannot open: {exc}") from exc
        self._can = can
        self._closed = False
        try:  # hardware filter on the protocol's 64 ids when the base allows a mask
            if base_id % ID_SPAN == 0:
                self._bus.set_filters([{"can_id": base_id, "can_mask": 0x7FF & ~(ID_SPAN - 1),
                                        "extended": False}])
        except Exception:  # noqa: BLE001 - software filtering in the reassembler still applies
            pass

    def send(self, msg) -> None:
        if self._closed:
            raise LinkError(f"{self.url}: link is closed")
        frames = can_pack(msg, self.role, self.base_id, self._seq)
        if len(frames) > 1:
            self._seq = (self._seq + 1) & 0x0F
        Message = self._can.Message
        for arbitration_id, data in frames:
            try:
                self._bus.send(Message(arbitration_id=arbitration_id, data=data, is_extended_id=False),
                               timeout=WRITE_TIMEOUT_S)
            except self._can.CanError as exc:
                raise LinkError(f"{self.url}: send failed: {exc}") from exc
            self.tx_frames += 1

    def recv(self, timeout_s: float | None = 0.0):
        if self._inbox:
            return self._inbox.popleft()
        if self._closed:
            raise LinkError(f"{self.url}: link is closed")
        deadline = _deadline(timeout_s)
        while True:
            try:
                frame = self._bus.recv(timeout=_remaining(deadline))
            except self._can.CanError as exc:
                raise LinkError(f"{self.url}: receive failed: {exc}") from exc
            if frame is None:
                return None
            if frame.is_extended_id or frame.is_remote_frame or frame.is_error_frame:
                self._reassembler.ignored_frames += 1
                continue
            self.rx_frames += 1
            offset = frame.arbitration_id - self.base_id
            if 0 <= offset < ID_SPAN and offset // ROLE_STRIDE == self.role:
                self.own_role_frames += 1  # another node with our role, or our own echo
                continue
            got = self._reassembler.feed(frame.arbitration_id, frame.data)
            if got is not None:
                return got[0]
            if deadline is not None and time.monotonic() >= deadline:
                return None

    @property
    def counters(self) -> dict[str, int]:
        c = self._reassembler.counters
        c.update(tx_frames=self.tx_frames, rx_frames=self.rx_frames, own_role_frames=self.own_role_frames)
        return c

    def close(self) -> None:
        if not self._closed:
            self._closed = True
            try:
                self._bus.shutdown()
            except Exception:  # noqa: BLE001
                pass


# ---------------------------------------------------------------- in-process pair

class _Pipe:
    def __init__(self) -> None:
        self.items: deque = deque()
        self.cond = threading.Condition()
        self.closed = False

    def put(self, items) -> None:
        with self.cond:
            self.items.extend(items)
            self.cond.notify_all()

    def get(self, timeout_s: float | None):
        with self.cond:
            if not self.items and not self.closed:
                self.cond.wait_for(lambda: self.items or self.closed, timeout_s)
            return self.items.popleft() if self.items else None


class PairLink(Link):
    """One end of an in-process pair. Messages still go through the real framing (serial bytes
    or CAN frames), so tests exercise the codec; thread-safe."""

    def __init__(self, name: str, tx: _Pipe, rx: _Pipe, framing: str, role: int) -> None:
        self.url = name
        self._tx, self._rx = tx, rx
        self._framing = framing
        self.role = role
        self._encoder = FrameEncoder()
        self._decoder = StreamDecoder()
        self._reassembler = CanReassembler()
        self._inbox: deque = deque()
        self._seq = 0
        self.tx_frames = 0

    def send(self, msg) -> None:
        if self._tx.closed:
            raise LinkError(f"{self.url}: link is closed")
        if self._framing == "serial":
            self._tx.put([self._encoder.encode(msg)])
            self.tx_frames += 1
        else:
            frames = can_pack(msg, self.role, DEFAULT_BASE_ID, self._seq)
            if len(frames) > 1:
                self._seq = (self._seq + 1) & 0x0F
            self._tx.put(frames)
            self.tx_frames += len(frames)

    def send_bytes(self, data: bytes) -> None:
        """Raw bytes to the other end (serial framing only): damaged frames for tests."""
        if self._framing != "serial":
            raise LinkError(f"{self.url}: send_bytes needs the serial framing")
        self._tx.put([bytes(data)])
        self.tx_frames += data.count(0)

    def recv(self, timeout_s: float | None = 0.0):
        if self._inbox:
            return self._inbox.popleft()
        deadline = _deadline(timeout_s)
        while True:
            item = self._rx.get(_remaining(deadline))
            if item is None:
                if self._rx.closed and not self._rx.items:
                    raise LinkError(f"{self.url}: the other end closed the link")
                return None
            if self._framing == "serial":
                self._inbox.extend(self._decoder.feed(item))
            else:
                got = self._reassembler.feed(*item)
                if got is not None:
                    self._inbox.append(got[0])
            if self._inbox:
                return self._inbox.popleft()

    @property
    def counters(self) -> dict[str, int]:
        c = self._decoder.counters if self._framing == "serial" else self._reassembler.counters
        c["tx_frames"] = self.tx_frames
        return c

    def close(self) -> None:
        for pipe in (self._tx, self._rx):
            with pipe.cond:
                pipe.closed = True
                pipe.cond.notify_all()


def make_pair(framing: str = "serial") -> tuple[PairLink, PairLink]:
    """Two connected in-process links: (bench end, controller end). framing: 'serial' or 'can'."""
    if framing not in ("serial", "can"):
        raise LinkError(f"make_pair: framing {framing!r}; expected 'serial' or 'can'")
    ab, ba = _Pipe(), _Pipe()
    return (PairLink(f"pair:{framing}:bench", ab, ba, framing, Role.BENCH),
            PairLink(f"pair:{framing}:controller", ba, ab, framing, Role.CONTROLLER))


# ---------------------------------------------------------------- link strings

def _option_value(text: str):
    low = text.lower()
    if low in ("true", "yes", "on"):
        return True
    if low in ("false", "no", "off"):
        return False
    for convert in (lambda t: int(t, 0), float):
        try:
            return convert(text)
        except ValueError:
            pass
    return text


def open_link(spec: str, role: int = Role.BENCH, **kwargs) -> Link:
    """Opens a serial or CAN link from its string: the ``serial:`` and ``can:`` back ends of the
    bench's one link registry (``hil.links.registry.connect``, which also knows exec:, lib:,
    qemu:, the stub's names and third-party link types). Use ``connect`` to name a board.

    serial:PORT[?baud=N]   PORT is a device path or any pyserial URL (loop://, socket://host:port);
                           a bare path or URL without the serial: prefix works too. Other query
                           options of a URL are pyserial's own.
    can:INTERFACE:CHANNEL[?bitrate=N&base_id=0x100&...]  any python-can interface; the other
                           options (and kwargs) go to can.Bus, e.g. sleep_after_open=0 for slcan.
    role is this end's role on CAN (the identifiers it sends with).
    """
    if spec.startswith("can:"):
        rest = spec[4:]
        head, _, query = rest.partition("?")
        interface, _, channel = head.partition(":")
        if not interface:
            raise LinkError(f"link '{spec}': expected can:INTERFACE:CHANNEL[?bitrate=N]")
        options = {k: _option_value(v) for k, v in parse_qsl(query, keep_blank_values=True)}
        options.update(kwargs)
        base_id = options.pop("base_id", DEFAULT_BASE_ID)
        bitrate = options.pop("bitrate", None)
        return CanLink(interface, channel or None, role=role, base_id=base_id, bitrate=bitrate, **options)
    port = spec[7:] if spec.startswith("serial:") else spec
    if not port:
        raise LinkError(f"link '{spec}': expected serial:PORT[?baud=N]")
    path, sep, query = port.partition("?")
    ours, theirs = {}, []
    for key, value in parse_qsl(query, keep_blank_values=True):
        if key in ("baud", "baudrate"):
            try:
                ours["baudrate"] = int(value)
            except ValueError:
                raise LinkError(f"link '{spec}': baud '{value}' is not an integer") from None
        elif key == "write_timeout_s":
            ours["write_timeout_s"] = float(value)
        else:
            theirs.append((key, value))
    if theirs and "://" not in path:
        raise LinkError(f"link '{spec}': unknown option(s) {', '.join(k for k, _ in theirs)}; "
                        f"a serial device takes baud=N")
    url = path + ("?" + urlencode(theirs) if theirs else "")
    ours.update(kwargs)
    return SerialLink(url, **ours)
