"""A misbehaving board for session tests: a thread on the master side of a pseudo-terminal.

The bench reaches it as ``serial:<slave path>`` exactly as it would a real
board, so the tests exercise the real link, codec and session code.
"""
from __future__ import annotations

import os
import select
import termios
import threading
import tty

from protocol.codec import FrameEncoder, StreamDecoder
from protocol.messages import (
    PROTOCOL_VERSION, Gates, Hello, ParamGet, ParamSet, ParamValue, Role, Sample, SampleSensors,
    Shutdown,
)

#: SENSOR_SET's parameter id (SPEC 8, read-only).
SENSOR_SET_ID = 8


class FakeBoard:
    """Answers like a board, with knobs to make it wrong.

    proto_version: the version its HELLO claims.
    answer_hello: False -> never answers HELLO.
    die_after_samples: closes its end of the line after answering this many SAMPLEs.
    """

    def __init__(self, proto_version: int = PROTOCOL_VERSION, answer_hello: bool = True,
                 die_after_samples: int | None = None, role: int = int(Role.CONTROLLER),
                 capabilities: int = 1, control_period_ns: int | None = None,
                 clamp: dict[int, float] | None = None, hello_raw: bytes | None = None,
                 on_sample=None, hello_after_tries: int = 1, known: set[int] | None = None,
                 sensor_set: float | None = None):
        """role, capabilities, control_period_ns (None: echo the bench's): its HELLO.
        clamp: parameter id -> the value it answers PARAM_SET with (status OK).
        hello_raw: bytes sent instead of a HELLO answer (garbage, frames of another version).
        on_sample(sample, encoder) -> bytes: what it writes for a SAMPLE (default GATES 0).
        hello_after_tries: answers only the n-th HELLO (1: the first).
        known: the parameter ids it knows (None: all); others are answered status 1 UNKNOWN.
        sensor_set: what it answers PARAM_GET of SENSOR_SET with (None: 0.0 like any other
        parameter it was not given; advertise CAP_SENSOR_SET in `capabilities` to be asked);
        a PARAM_SET of it is answered READ_ONLY. Every SAMPLE and SAMPLE_SENSORS it gets is in
        `received` and answered alike."""
        self.proto_version = proto_version
        self.answer_hello = answer_hello
        self.die_after_samples = die_after_samples
        self.role, self.capabilities = role, capabilities
        self.control_period_ns = control_period_ns
        self.clamp = clamp or {}
        self.hello_raw = hello_raw
        self.on_sample = on_sample
        self.hello_after_tries = hello_after_tries
        self.known = known
        self.sensor_set = sensor_set
        self.hellos = 0
        self.master, slave = os.openpty()
        tty.setraw(slave, termios.TCSANOW)
        self.slave_path = os.ttyname(slave)
        # Held open while the board runs: reading a master whose slave nobody has open fails (EIO).
        self._slave = slave
        self.params: dict[int, float] = {}
        self.samples = 0
        self.received: list = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._serve, daemon=True)

    @property
    def url(self) -> str:
        return f"serial:{self.slave_path}"

    def __enter__(self) -> "FakeBoard":
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join(2.0)
        if self.master >= 0:
            os.close(self.master)
            self.master = -1
        os.close(self._slave)

    def _write(self, encoder: FrameEncoder, msg) -> None:
        os.write(self.master, encoder.encode(msg))

    def _serve(self) -> None:
        enc, dec = FrameEncoder(), StreamDecoder()
        while not self._stop.is_set():
            ready, _, _ = select.select([self.master], [], [], 0.05)
            if not ready:
                continue
            try:
                data = os.read(self.master, 4096)
            except OSError:
                return
            for msg in dec.feed(data):
                self.received.append(msg)
                if isinstance(msg, Hello):
                    self.hellos += 1
                    if not self.answer_hello or self.hellos < self.hello_after_tries:
                        continue
                    if self.hello_raw is not None:
                        os.write(self.master, self.hello_raw)
                        continue
                    name = b"fake-board"
                    period = msg.control_period_ns if self.control_period_ns is None \
                        else self.control_period_ns
                    self._write(enc, Hello(proto_version=self.proto_version, role=self.role,
                                           capabilities=self.capabilities,
                                           control_period_ns=period,
                                           name_len=len(name), name=name))
                elif isinstance(msg, (ParamSet, ParamGet)) and self.known is not None \
                        and msg.id not in self.known:
                    self._write(enc, ParamValue(id=msg.id, status=1, value=0.0))
                elif isinstance(msg, (ParamSet, ParamGet)) and msg.id == SENSOR_SET_ID \
                        and self.sensor_set is not None:
                    status = 3 if isinstance(msg, ParamSet) else 0      # READ_ONLY
                    self._write(enc, ParamValue(id=msg.id, status=status,
                                                value=float(self.sensor_set)))
                elif isinstance(msg, ParamSet):
                    self.params[msg.id] = self.clamp.get(msg.id, msg.value)
                    self._write(enc, ParamValue(id=msg.id, status=0, value=self.params[msg.id]))
                elif isinstance(msg, ParamGet):
                    self._write(enc, ParamValue(id=msg.id, status=0, value=self.params.get(msg.id, 0.0)))
                elif isinstance(msg, (Sample, SampleSensors)):
                    if self.die_after_samples is not None and self.samples >= self.die_after_samples:
                        os.close(self.master)
                        self.master = -1
                        return
                    self.samples += 1
                    if self.on_sample is not None:
                        data = self.on_sample(msg, enc)
                        if data:
                            os.write(self.master, data)
                    else:
                        self._write(enc, Gates(period=msg.period, gates=0))
                elif isinstance(msg, Shutdown):
                    return
