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
    PROTOCOL_VERSION, Gates, Hello, ParamGet, ParamSet, ParamValue, Role, Sample, Shutdown,
)


class FakeBoard:
    """Answers like a board, with knobs to make it wrong.

    proto_version: the version its HELLO claims.
    answer_hello: False -> never answers HELLO.
    die_after_samples: closes its end of the line after answering this many SAMPLEs.
    """

    def __init__(self, proto_version: int = PROTOCOL_VERSION, answer_hello: bool = True,
                 die_after_samples: int | None = None):
        self.proto_version = proto_version
        self.answer_hello = answer_hello
        self.die_after_samples = die_after_samples
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
                if isinstance(msg, Hello) and self.answer_hello:
                    name = b"fake-board"
                    self._write(enc, Hello(proto_version=self.proto_version,
                                           role=int(Role.CONTROLLER), capabilities=1,
                                           control_period_ns=msg.control_period_ns,
                                           name_len=len(name), name=name))
                elif isinstance(msg, ParamSet):
                    self.params[msg.id] = msg.value
                    self._write(enc, ParamValue(id=msg.id, status=0, value=msg.value))
                elif isinstance(msg, ParamGet):
                    self._write(enc, ParamValue(id=msg.id, status=0, value=self.params.get(msg.id, 0.0)))
                elif isinstance(msg, Sample):
                    if self.die_after_samples is not None and self.samples >= self.die_after_samples:
                        os.close(self.master)
                        self.master = -1
                        return
                    self.samples += 1
                    self._write(enc, Gates(period=msg.period, gates=0))
                elif isinstance(msg, Shutdown):
                    return
