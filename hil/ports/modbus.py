"""Modbus control port: lab tools and PLC-style sequencers drive the bench over Modbus TCP
(or RTU on a serial port) while it runs.

The pymodbus 3.16 server runs off the plant's hot path, in a thread with its own asyncio
loop or (``isolation="process"``) in a process of its own; a request costs 0.1-0.3 ms of
Python there. Between it and the session sits a :class:`ControlMailbox` in shared memory:

* the session tests ``mailbox.pending`` / calls ``mailbox.take_requests()`` once per
  period: one shared-counter comparison when nothing is pending, else the writes since
  the last call (latest value wins);
* the session calls ``mailbox.publish(snapshot)`` every N periods: a copy of a dozen
  numbers; the server turns the latest snapshot into registers only when a client reads.

Neither call ever waits for the port (they only *try* its lock). The register map
(:data:`HOLDING_REGISTERS`, :data:`INPUT_REGISTERS`, coils and discrete inputs) is
rendered into docs/modbus.md by :func:`register_map_markdown`. Uses the pymodbus 3.16
``SimDevice``/``SimData`` datastore (``ModbusDeviceContext``/``ModbusServerContext`` are
deprecated for v4) with an ``action`` hook that validates writes and fills read registers.
"""
from __future__ import annotations

import asyncio
import ctypes
import enum
import math
import multiprocessing
import signal
import socket
import threading
from dataclasses import dataclass, replace
from typing import Any, NamedTuple

from pymodbus.constants import ExcCodes
from pymodbus.framer import FramerType
from pymodbus.server import ModbusSerialServer, ModbusTcpServer
from pymodbus.simulator import DataType, SimData, SimDevice

from hil.control_inputs import UNBOUNDED, ControlInputError, ControlLimits

REGISTER_MAP_VERSION = 2  # 2: speed_reference (holding 5-6)
_TYPES = {"int16": (1, True), "uint16": (1, False), "int32": (2, True), "uint32": (2, False)}


@dataclass(frozen=True)
class RegisterField:
    """One value in the register map: `address` is the 0-based PDU address; 32-bit values
    take two registers, high word first; engineering value = raw * scale."""

    name: str
    address: int
    type: str
    scale: float
    unit: str
    description: str

    @property
    def count(self) -> int:
        return _TYPES[self.type][0]

    def encode(self, value: float) -> list[int]:
        """Engineering value -> registers (rounded, saturated at the type's range)."""
        words, signed = _TYPES[self.type]
        bits = 16 * words
        lo, hi = (-(1 << (bits - 1)), (1 << (bits - 1)) - 1) if signed else (0, (1 << bits) - 1)
        try:
            raw = round(value / self.scale)
        except (ValueError, OverflowError):  # NaN or infinity
            raw = 0 if value != value else (hi if value > 0 else lo)
        raw = min(max(raw, lo), hi) & ((1 << bits) - 1)
        return [raw >> 16, raw & 0xFFFF] if words == 2 else [raw]

    def decode(self, registers: list[int]) -> float | int:
        words, signed = _TYPES[self.type]
        raw = (registers[0] << 16) | registers[1] if words == 2 else registers[0]
        if signed and raw >= 1 << (16 * words - 1):
            raw -= 1 << (16 * words)
        return raw * self.scale if self.scale != 1 else raw


HOLDING_REGISTERS = (
    RegisterField("load_torque", 0, "int16", 0.001, "N·m",
                  "load torque T_L in J dω/dt = T_e - T_L - Bω"),
    RegisterField("dc_link_voltage_setpoint", 1, "uint16", 0.01, "V", "DC-link voltage of the emulated supply"),
    RegisterField("run", 2, "uint16", 1, "-", "1 run, 0 stop (gates off, the motor coasts); other values refused"),
    RegisterField("fault_injection", 3, "uint32", 1, "bits",
                  "fault-injection bits (meaning defined by the fault-injection module); also coils 0-31"),
    RegisterField("speed_reference", 5, "int32", 0.01, "rpm",
                  "the board's speed reference (COMMAND speed_ref_rpm); written values are sent at once"),
)
INPUT_REGISTERS = (
    RegisterField("speed", 0, "int32", 0.01, "rpm", "mechanical speed"),
    RegisterField("i_a", 2, "int16", 0.01, "A", "phase a current"),
    RegisterField("i_b", 3, "int16", 0.01, "A", "phase b current"),
    RegisterField("i_c", 4, "int16", 0.01, "A", "phase c current"),
    RegisterField("torque", 5, "int16", 0.001, "N·m", "electromagnetic torque"),
    RegisterField("dc_link_voltage", 6, "uint16", 0.01, "V", "DC-link voltage"),
    RegisterField("period_counter", 7, "uint32", 1, "periods", "control periods completed"),
    RegisterField("deadline_misses", 9, "uint32", 1, "periods", "periods late or missed (real-time clock)"),
    RegisterField("state", 11, "uint16", 1, "bits", "state bits (StateBit); also discrete inputs 0-15"),
    RegisterField("load_torque_applied", 12, "int16", 0.001, "N·m", "load torque in effect (any source)"),
    RegisterField("fault_bits_active", 13, "uint32", 1, "bits", "fault-injection bits in effect (any source)"),
    RegisterField("map_version", 15, "uint16", 1, "-", f"version of this register map ({REGISTER_MAP_VERSION})"),
)
FAULT_COILS = 32  # coils 0..31 mirror the fault_injection holding registers, coil n = bit n


class StateBit(enum.IntFlag):
    """Bits of the `state` input register (and discrete inputs 0-15)."""

    RUNNING = 0x01  # the session is advancing the plant with the board in the loop
    SAFE_STATE = 0x02  # the inverter is held with all gates off
    BOARD_FAULT = 0x04  # the board reported a FAULT
    FAULT_INJECTED = 0x08  # at least one injected fault is active
    DEADLINE_BUDGET_EXCEEDED = 0x10  # the real-time clock missed more deadlines than allowed
    REAL_TIME = 0x20  # clock mode: real time (clear: lockstep)


@dataclass(frozen=True)
class ControlRequests:
    """Writes received since the last ``take_requests()``; None = not written."""

    load_torque_nm: float | None = None
    dc_link_voltage_v: float | None = None
    run: bool | None = None
    fault_bits: int | None = None
    speed_ref_rpm: float | None = None


class PlantSnapshot(NamedTuple):
    """What the session publishes for the input registers (a NamedTuple: cheap to make)."""

    speed_rpm: float
    i_a_a: float
    i_b_a: float
    i_c_a: float
    torque_nm: float
    dc_link_voltage_v: float
    period: int
    deadline_misses: int = 0
    state: int = 0
    load_torque_nm: float = 0.0
    fault_bits: int = 0


_SNAPSHOT_OF_INPUT = {"speed": "speed_rpm", "i_a": "i_a_a", "i_b": "i_b_a", "i_c": "i_c_a", "torque": "torque_nm",
                      "dc_link_voltage": "dc_link_voltage_v", "period_counter": "period",
                      "deadline_misses": "deadline_misses", "state": "state",
                      "load_torque_applied": "load_torque_nm", "fault_bits_active": "fault_bits"}


_WRITTEN_BITS = {"load_torque_nm": 1, "dc_link_voltage_v": 2, "run": 4, "fault_bits": 8, "speed_ref_rpm": 16}
_INT_SNAPSHOT_FIELDS = frozenset({"period", "deadline_misses", "state", "fault_bits"})


class _Shared(ctypes.Structure):
    """The mailbox's state, in memory shared with the port (thread or process)."""

    _fields_ = [
        ("request_seq", ctypes.c_uint64),  # bumped by the port after each accepted write
        ("written", ctypes.c_uint32),  # _WRITTEN_BITS written since the session's last take
        ("run", ctypes.c_uint32),
        ("fault_bits", ctypes.c_uint64),
        ("load_torque_nm", ctypes.c_double),
        ("dc_link_voltage_v", ctypes.c_double),
        ("speed_ref_rpm", ctypes.c_double),
        ("snapshot_seq", ctypes.c_uint64),  # 0: nothing published yet
        ("snapshot", ctypes.c_double * len(PlantSnapshot._fields)),
        ("requests_served", ctypes.c_uint64),
        ("publishes_skipped", ctypes.c_uint64),
        ("writes_refused", ctypes.c_uint64),  # writes outside ControlLimits (exception 3)
    ]


class ControlMailbox:
    """Hand-over between the Modbus port (its thread or process) and the session.

    State lives in shared memory guarded by a process-shared lock. The session never
    waits for it: ``pending`` is one shared-counter comparison, and ``take_requests`` /
    ``publish`` only *try* the lock (the port holds it for microseconds); if it is busy
    they give up for this period (take returns None, the writes stay pending; the
    publish is skipped and counted, the next one comes N periods later).
    """

    __slots__ = ("_shared", "_lock", "_seen_seq")

    def __init__(self, load_torque_nm: float = 0.0, dc_link_voltage_v: float = 0.0, run: bool = False,
                 fault_bits: int = 0, speed_ref_rpm: float = 0.0):
        ctx = multiprocessing.get_context("spawn")
        self._shared = ctx.RawValue(_Shared)
        self._lock = ctx.Lock()
        self._seen_seq = 0
        sh = self._shared
        sh.load_torque_nm, sh.dc_link_voltage_v = float(load_torque_nm), float(dc_link_voltage_v)
        sh.run, sh.fault_bits = int(bool(run)), int(fault_bits)
        sh.speed_ref_rpm = float(speed_ref_rpm)

    # -- session side -------------------------------------------------------------------------------
    @property
    def pending(self) -> bool:
        """True when the port accepted writes the session has not taken yet."""
        return self._shared.request_seq != self._seen_seq

    def take_requests(self) -> ControlRequests | None:
        """Writes since the last take (latest value of each), or None: nothing pending, or
        the port is writing right now (then the writes come with the next call)."""
        sh = self._shared
        if sh.request_seq == self._seen_seq:
            return None
        if not self._lock.acquire(False):
            return None
        try:
            self._seen_seq = sh.request_seq
            written, sh.written = sh.written, 0
            values = (sh.load_torque_nm, sh.dc_link_voltage_v, bool(sh.run), int(sh.fault_bits),
                      sh.speed_ref_rpm)
        finally:
            self._lock.release()
        if not written:
            return None
        return ControlRequests(*(v if written & bit else None for v, bit in zip(values, _WRITTEN_BITS.values())))

    def publish(self, snapshot: PlantSnapshot) -> None:
        """Make `snapshot` the one served to readers (a copy into shared memory)."""
        sh = self._shared
        if not self._lock.acquire(False):
            sh.publishes_skipped += 1
            return
        try:
            sh.snapshot[:] = snapshot
            sh.snapshot_seq += 1
        finally:
            self._lock.release()

    # -- port side ------------------------------------------------------------------------------------
    def request(self, **changes: Any) -> bool:
        """Record writes (ControlRequests field names) for the session's next take.
        Returns False if the lock could not be had within a second."""
        unknown = set(changes) - set(_WRITTEN_BITS)
        if unknown:
            raise TypeError(f"unknown request field(s) {', '.join(sorted(unknown))}")
        if not self._lock.acquire(timeout=1.0):
            return False
        try:
            sh = self._shared
            for name, value in changes.items():
                setattr(sh, name, int(value) if name in ("run", "fault_bits") else float(value))
                sh.written |= _WRITTEN_BITS[name]
            sh.request_seq += 1
        finally:
            self._lock.release()
        return True

    def commanded(self) -> ControlRequests:
        """The values last commanded over the port (or the initial ones), all fields set."""
        with self._lock:
            sh = self._shared
            return ControlRequests(sh.load_torque_nm, sh.dc_link_voltage_v, bool(sh.run), int(sh.fault_bits),
                                   sh.speed_ref_rpm)

    def snapshot(self) -> PlantSnapshot | None:
        """The latest published snapshot, or None before the first."""
        with self._lock:
            if not self._shared.snapshot_seq:
                return None
            values = list(self._shared.snapshot)
        return PlantSnapshot(*(int(v) if name in _INT_SNAPSHOT_FIELDS else v
                               for name, v in zip(PlantSnapshot._fields, values)))

    @property
    def publishes_skipped(self) -> int:
        return self._shared.publishes_skipped

    @property
    def requests_served(self) -> int:
        """Modbus requests the port has handled (reads and writes)."""
        return self._shared.requests_served

    @property
    def writes_refused(self) -> int:
        """Writes the port refused (a value outside its ControlLimits: exception 3)."""
        return self._shared.writes_refused

    def _count_refusal(self) -> None:
        self._shared.writes_refused += 1  # only the port writes it; a statistic, no lock

    def _count_request(self) -> None:
        self._shared.requests_served += 1  # only the port writes it; a statistic, no lock


def _block(fields: tuple[RegisterField, ...]) -> list[SimData]:
    return [SimData(f.address, count=f.count, values=0, datatype=DataType.REGISTERS) for f in fields]


@dataclass(frozen=True)
class _PortConfig:
    host: str | None
    port: int
    rtu_port: str | None
    rtu_baudrate: int
    rtu_device_id: int
    load_torque_limit_nm: float | None
    dc_link_voltage_limit_v: float | None
    fault_bits_mask: int
    speed_ref_limit_rpm: float | None = None
    limits: ControlLimits = UNBOUNDED


class _PortServer:
    """The pymodbus servers and the request handling; runs in the port's thread or process."""

    def __init__(self, config: _PortConfig, mailbox: ControlMailbox):
        self.config = config
        self.mailbox = mailbox
        self.tcp_address: tuple[str, int] | None = None

    async def serve(self, started, stop: asyncio.Event) -> None:
        """Start the servers, call started(tcp_address), serve until `stop` is set."""
        cfg = self.config
        servers = []
        try:
            if cfg.host is not None:
                tcp = ModbusTcpServer(self._device(), address=(cfg.host, cfg.port))
                try:
                    await tcp.serve_forever(background=True)
                except RuntimeError:
                    raise self._tcp_error() from None
                servers.append(tcp)
                self.tcp_address = tuple(tcp.transport.sockets[0].getsockname()[:2])
            if cfg.rtu_port is not None:
                rtu = ModbusSerialServer(self._device(cfg.rtu_device_id), framer=FramerType.RTU, port=cfg.rtu_port,
                                         baudrate=cfg.rtu_baudrate)
                try:
                    await rtu.serve_forever(background=True)
                except RuntimeError:
                    raise self._rtu_error() from None
                servers.append(rtu)
            started(self.tcp_address)
            await stop.wait()
        finally:
            for server in servers:
                await server.shutdown()

    def _tcp_error(self) -> OSError:
        """pymodbus only says it could not listen; find out why by binding ourselves."""
        host, port = self.config.host, self.config.port
        probe = socket.socket(socket.AF_INET6 if ":" in host else socket.AF_INET)
        try:
            probe.bind((host, port))
        except OSError as exc:
            return type(exc)(exc.errno, f"Modbus TCP: cannot listen on {host}:{port}: {exc.strerror}")
        finally:
            probe.close()
        return OSError(f"Modbus TCP: cannot listen on {host}:{port}")

    def _rtu_error(self) -> OSError:
        import serial  # pyserial, which pymodbus uses for the port

        name = self.config.rtu_port
        try:
            serial.serial_for_url(name, baudrate=self.config.rtu_baudrate).close()
        except (serial.SerialException, ValueError) as exc:
            return OSError(f"Modbus RTU: cannot open serial port {name!r}: {exc}")
        return OSError(f"Modbus RTU: cannot open serial port {name!r}")

    def _device(self, device_id: int = 0) -> SimDevice:
        """device_id 0 answers every unit id (Modbus TCP, where the unit id only matters behind
        a gateway); on an RTU line, where other devices share the bus, only our own."""
        coils = [SimData(0, count=FAULT_COILS, values=False, datatype=DataType.BITS)]
        discrete = [SimData(0, count=16, values=False, datatype=DataType.BITS)]
        return SimDevice(id=device_id, simdata=(coils, discrete, _block(HOLDING_REGISTERS), _block(INPUT_REGISTERS)),
                         action=self._action)

    async def _action(self, function_code: int, start_address: int, address: int, count: int,
                      registers: list[int], values: list[int] | list[bool] | None) -> ExcCodes | None:
        """pymodbus calls this before every access: fill what is read, validate what is written."""
        self.mailbox._count_request()
        if function_code == 4:
            self._fill_inputs(registers)
        elif function_code == 2:
            snapshot = self.mailbox.snapshot()
            registers[0] = (snapshot.state if snapshot is not None else 0) & 0xFFFF
        elif function_code in (1, 5, 15):
            bits = self.mailbox.commanded().fault_bits
            registers[0], registers[1] = bits & 0xFFFF, (bits >> 16) & 0xFFFF
            if values is not None:
                for i, value in enumerate(values):
                    bit = 1 << (address + i)
                    bits = (bits | bit) if value else (bits & ~bit)
                return self._apply({"fault_injection": bits})
        else:  # holding registers: 3, 6, 16, 22, 23
            current = self.mailbox.commanded()
            regs = (HOLDING_REGISTERS[0].encode(current.load_torque_nm)
                    + HOLDING_REGISTERS[1].encode(current.dc_link_voltage_v)
                    + [int(current.run)] + HOLDING_REGISTERS[3].encode(current.fault_bits)
                    + HOLDING_REGISTERS[4].encode(current.speed_ref_rpm))
            registers[:len(regs)] = regs
            if values is not None:
                first = address - start_address
                last = first + len(values)
                new = regs.copy()
                new[first:last] = values
                # every value the write touches is posted, even if unchanged: writing the
                # current register value must still override a plan's setting
                touched = {f.name: f.decode(new[f.address:f.address + f.count]) for f in HOLDING_REGISTERS
                           if f.address < last and first < f.address + f.count}
                return self._apply(touched)
        return None

    def _apply(self, changed: dict[str, float | int]) -> ExcCodes | None:
        """Validate decoded writes (hil.control_inputs, the one validator of every
        control input) and post them to the mailbox; all or nothing."""
        limits = self.config.limits
        requests: dict[str, Any] = {}
        try:
            for name, value in changed.items():
                if name == "load_torque":
                    requests["load_torque_nm"] = round(limits.torque_nm(value), 3)
                elif name == "dc_link_voltage_setpoint":
                    requests["dc_link_voltage_v"] = round(limits.dc_link_voltage_v(value), 2)
                elif name == "run":
                    if value not in (0, 1):
                        raise ControlInputError("run", value, "1 runs, 0 stops")
                    requests["run"] = bool(value)
                elif name == "fault_injection":
                    requests["fault_bits"] = limits.fault_bits(int(value))
                elif name == "speed_reference":
                    requests["speed_ref_rpm"] = round(limits.speed_ref_rpm(value), 2)
        except ControlInputError:
            self.mailbox._count_refusal()
            return ExcCodes.ILLEGAL_VALUE
        if requests and not self.mailbox.request(**requests):
            return ExcCodes.DEVICE_BUSY
        return None

    def _fill_inputs(self, registers: list[int]) -> None:
        snapshot = self.mailbox.snapshot()
        values = {} if snapshot is None else snapshot._asdict()
        for f in INPUT_REGISTERS:
            value = REGISTER_MAP_VERSION if f.name == "map_version" else values.get(_SNAPSHOT_OF_INPUT[f.name], 0)
            registers[f.address:f.address + f.count] = f.encode(value)


def _process_main(config: _PortConfig, mailbox: ControlMailbox, conn) -> None:
    """Entry point of the port's own process: serve until the parent says stop or goes away."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the parent's to handle
    server = _PortServer(config, mailbox)

    async def main() -> None:
        stop = asyncio.Event()
        loop = asyncio.get_running_loop()

        def on_parent() -> None:
            try:
                conn.recv()  # "stop"
            except EOFError:  # the parent died
                pass
            loop.remove_reader(conn.fileno())
            stop.set()

        loop.add_reader(conn.fileno(), on_parent)
        await server.serve(lambda address: conn.send(("ready", address)), stop)

    try:
        asyncio.run(main())
    except Exception as exc:  # noqa: BLE001 - reported to the parent's start()
        try:
            conn.send(("error", exc))
        except (BrokenPipeError, OSError):
            pass


class ModbusPort:
    """Modbus TCP server on ``host:port`` (127.0.0.1 unless told otherwise; port 0 picks a
    free one, see :attr:`tcp_address`) and optionally Modbus RTU on serial port
    ``rtu_port``. Over TCP it answers any unit id; on the RTU line only ``rtu_device_id``
    (1-247, default 1), so it can share an RS-485 bus with other devices.

    ``isolation``: "thread" runs the server in a thread of this process with its own
    asyncio loop; "process" runs it in a spawned process, so that handling a request
    never holds this process's GIL (in a thread each request stalls the session for
    about 0.1-0.6 ms: see docs/modbus.md). Writes outside ``limits`` (a
    hil.control_inputs.ControlLimits, usually ``ControlLimits.from_profile``), or
    outside ``load_torque_limit_nm`` (absolute), ``dc_link_voltage_limit_v``,
    ``fault_bits_mask`` or ``speed_ref_limit_rpm`` (absolute) where given, are refused with
    Modbus exception 3 (illegal data value) and counted (``mailbox.writes_refused``)."""

    def __init__(self, mailbox: ControlMailbox, host: str | None = "127.0.0.1", port: int = 5020,
                 rtu_port: str | None = None, *, rtu_baudrate: int = 19200, rtu_device_id: int = 1,
                 load_torque_limit_nm: float | None = None,
                 dc_link_voltage_limit_v: float | None = None, fault_bits_mask: int = 0xFFFFFFFF,
                 speed_ref_limit_rpm: float | None = None, limits: ControlLimits | None = None,
                 isolation: str = "thread", start_timeout_s: float = 10.0):
        if host is None and rtu_port is None:
            raise ValueError("ModbusPort: give a TCP host or an RTU serial port (or both)")
        if not (isinstance(rtu_device_id, int) and 1 <= rtu_device_id <= 247):
            raise ValueError(f"ModbusPort rtu_device_id {rtu_device_id!r}: an RTU device id is 1..247")
        if isolation not in ("thread", "process"):
            raise ValueError(f"ModbusPort isolation {isolation!r}: use 'thread' or 'process'")
        self.mailbox = mailbox
        self.host = host
        self.port = port
        self.rtu_port = rtu_port
        self.isolation = isolation
        self.start_timeout_s = start_timeout_s
        # The ranges: a profile's ControlLimits, each explicit limit given here overriding it.
        limits = limits if limits is not None else UNBOUNDED
        explicit = {"load_torque_max_nm": load_torque_limit_nm, "dc_link_max_v": dc_link_voltage_limit_v,
                    "speed_ref_max_rpm": speed_ref_limit_rpm,
                    "fault_bits_mask": None if limits.fault_bits_mask is not None and fault_bits_mask == 0xFFFFFFFF
                    else fault_bits_mask}
        limits = replace(limits, **{k: v for k, v in explicit.items() if v is not None})
        self._config = _PortConfig(host, port, rtu_port, rtu_baudrate, rtu_device_id, load_torque_limit_nm,
                                   dc_link_voltage_limit_v, fault_bits_mask, speed_ref_limit_rpm, limits)
        self.tcp_address: tuple[str, int] | None = None
        self._thread: threading.Thread | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._stop_event: asyncio.Event | None = None
        self._process = None
        self._conn = None

    @property
    def requests_served(self) -> int:
        return self.mailbox.requests_served

    # -- life cycle -------------------------------------------------------------------------------
    def start(self) -> ModbusPort:
        if self.running:
            raise RuntimeError("ModbusPort already started")
        if self.isolation == "thread":
            self._start_thread()
        else:
            self._start_process()
        return self

    def stop(self, timeout_s: float = 5.0) -> None:
        """Stop the server and join its thread or process. Idempotent."""
        if self._thread is not None:
            thread, loop, event = self._thread, self._loop, self._stop_event
            if loop is not None and event is not None:
                try:
                    loop.call_soon_threadsafe(event.set)
                except RuntimeError:  # the loop has already closed
                    pass
            thread.join(timeout_s)
            if thread.is_alive():
                raise TimeoutError(f"Modbus port thread did not stop within {timeout_s} s")
            self._thread = None
        if self._process is not None:
            process, conn = self._process, self._conn
            try:
                conn.send("stop")
            except (BrokenPipeError, OSError):
                pass
            process.join(timeout_s)
            if process.is_alive():
                process.kill()
                process.join(timeout_s)
            conn.close()
            self._process = self._conn = None

    def __enter__(self) -> ModbusPort:
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()

    @property
    def running(self) -> bool:
        if self._thread is not None:
            return self._thread.is_alive()
        return self._process is not None and self._process.is_alive()

    def _start_thread(self) -> None:
        ready = threading.Event()
        outcome: list[Any] = []
        server = _PortServer(self._config, self.mailbox)

        def started(address) -> None:
            outcome.append(("ready", address))
            ready.set()

        def main() -> None:
            loop = asyncio.new_event_loop()
            self._loop = loop
            self._stop_event = asyncio.Event()
            try:
                loop.run_until_complete(server.serve(started, self._stop_event))
            except BaseException as exc:  # noqa: BLE001 - reported to start()
                outcome.append(("error", exc))
            finally:
                ready.set()
                loop.close()

        self._thread = threading.Thread(target=main, name="modbus-port", daemon=True)
        self._thread.start()
        if not ready.wait(self.start_timeout_s):
            self.stop()
            raise TimeoutError(f"Modbus port did not start within {self.start_timeout_s} s")
        kind, value = outcome[0]
        if kind == "error":
            self._thread.join(self.start_timeout_s)
            self._thread = None
            raise value
        self.tcp_address = value

    def _start_process(self) -> None:
        ctx = multiprocessing.get_context("spawn")
        parent, child = ctx.Pipe()
        process = ctx.Process(target=_process_main, args=(self._config, self.mailbox, child),
                              name="hil-modbus-port", daemon=True)
        process.start()
        child.close()
        self._process, self._conn = process, parent
        try:
            if not parent.poll(self.start_timeout_s):
                raise TimeoutError(f"Modbus port process did not start within {self.start_timeout_s} s")
            kind, value = parent.recv()
        except EOFError:
            process.join(self.start_timeout_s)
            kind, value = "error", RuntimeError(
                f"Modbus port process exited with status {process.exitcode} before serving (a script "
                "that starts it must guard its top level with `if __name__ == '__main__':`, the rule "
                "of multiprocessing's spawn)")
        except BaseException:
            self.stop()
            raise
        if kind == "error":
            self.stop()
            raise value
        self.tcp_address = value


def _range(f: RegisterField) -> str:
    if f.unit in ("bits", "-"):
        return "-"
    words, signed = _TYPES[f.type]
    top = (1 << (16 * words - (1 if signed else 0))) - 1
    decimals = max(0, -math.floor(math.log10(f.scale))) if f.scale < 1 else 0
    high = f"{top * f.scale:.{decimals}f}"
    return f"±{high}" if signed else f"0 to {high}"


def register_map_markdown() -> str:
    """The register map as markdown tables (the source of docs/modbus.md's tables)."""
    def table(title: str, fc: str, fields: tuple[RegisterField, ...]) -> list[str]:
        rows = [f"**{title}** ({fc})", "",
                "| address | 1-based | name | type | scale | unit | range | meaning |",
                "|---|---|---|---|---|---|---|---|"]
        base = 40001 if "holding" in title.lower() else 30001
        for f in fields:
            addr = str(f.address) if f.count == 1 else f"{f.address}-{f.address + f.count - 1}"
            one = str(base + f.address) if f.count == 1 else f"{base + f.address}-{base + f.address + f.count - 1}"
            scale = "1" if f.scale == 1 else f"{f.scale:g}"
            rows.append(f"| {addr} | {one} | `{f.name}` | {f.type} | {scale} | {f.unit} | {_range(f)} | "
                        f"{f.description} |")
        return rows + [""]

    lines = table("Holding registers", "read FC 3, write FC 6/16/22/23", HOLDING_REGISTERS)
    lines += table("Input registers", "read FC 4", INPUT_REGISTERS)
    lines += ["**Coils** (read FC 1, write FC 5/15): coil *n* (0-31) is fault-injection bit *n*, the same "
              "bits as holding registers 3-4.", "",
              "**Discrete inputs** (read FC 2): input *n* (0-15) is bit *n* of the `state` input register:", "",
              "| bit | name | meaning |", "|---|---|---|"]
    meanings = {
        StateBit.RUNNING: "the session is advancing the plant with the board in the loop",
        StateBit.SAFE_STATE: "the inverter is held with all gates off",
        StateBit.BOARD_FAULT: "the board reported a FAULT",
        StateBit.FAULT_INJECTED: "at least one injected fault is active",
        StateBit.DEADLINE_BUDGET_EXCEEDED: "the real-time clock missed more deadlines than allowed",
        StateBit.REAL_TIME: "clock mode is real time (clear: lockstep)",
    }
    for bit in StateBit:
        lines.append(f"| {bit.value.bit_length() - 1} | `{bit.name}` | {meanings[bit]} |")
    return "\n".join(lines) + "\n"
