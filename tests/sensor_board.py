"""A sensor-set board for session tests (SPEC 6.13): it advertises SENSOR_SET, answers PARAM_GET
of SENSOR_SET with the value it is given (a good mask, or a wrong one: NaN, a fraction,
reserved bits), records every SAMPLE and SAMPLE_SENSORS it gets and answers each with GATES 0.

Where it sits:

- ``can``: a thread on a python-can virtual bus (``CanSensorBoard``); the bench opens
  ``can:virtual:CHANNEL``;
- ``exec``: this file run as a program on the pty the bench's ``exec:`` link makes
  (``exec_url``), the board as its own process, writing what it received as JSON lines to the
  file after ``--record``;
- over a pseudo-terminal in a thread: tests/fake_board.py's FakeBoard with ``sensor_set=``.

    python tests/sensor_board.py --sensor-set 0x2b --record got.jsonl     # on stdin/stdout
"""
from __future__ import annotations

import argparse
import itertools
import json
import os
import select
import sys
import threading
from dataclasses import fields
from pathlib import Path

if __package__ in (None, ""):      # run as a program: the repository on the path
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from protocol.messages import (  # noqa: E402
    CAP_GATES, CAP_SENSOR_SET, PROTOCOL_VERSION, Gates, Hello, ParamGet, ParamSet, ParamValue,
    Role, Sample, SampleSensors, Shutdown,
)

SENSOR_SET_ID = 8
READ_ONLY = 3


class SensorBoardLogic:
    """What the board answers, whatever carries it: `react(msg)` -> the messages to send."""

    def __init__(self, sensor_set: float, capabilities: int = CAP_GATES | CAP_SENSOR_SET):
        self.sensor_set = sensor_set
        self.capabilities = capabilities
        self.params: dict[int, float] = {}
        self.samples: list = []          # every SAMPLE and SAMPLE_SENSORS, as received

    def react(self, msg) -> list:
        if isinstance(msg, Hello):
            name = b"sensor-board"
            return [Hello(proto_version=PROTOCOL_VERSION, role=int(Role.CONTROLLER),
                          capabilities=self.capabilities, control_period_ns=msg.control_period_ns,
                          name_len=len(name), name=name)]
        if isinstance(msg, ParamGet) and msg.id == SENSOR_SET_ID:
            return [ParamValue(id=msg.id, status=0, value=float(self.sensor_set))]
        if isinstance(msg, ParamSet) and msg.id == SENSOR_SET_ID:
            return [ParamValue(id=msg.id, status=READ_ONLY, value=float(self.sensor_set))]
        if isinstance(msg, ParamSet):
            self.params[msg.id] = msg.value
            return [ParamValue(id=msg.id, status=0, value=msg.value)]
        if isinstance(msg, ParamGet):
            return [ParamValue(id=msg.id, status=0, value=self.params.get(msg.id, 0.0))]
        if isinstance(msg, (Sample, SampleSensors)):
            self.samples.append(msg)
            return [Gates(period=msg.period, gates=0)]
        return []


def sample_record(msg) -> dict:
    """A received SAMPLE or SAMPLE_SENSORS as plain data (its type and fields)."""
    return {"type": type(msg).__name__, **{f.name: getattr(msg, f.name) for f in fields(msg)}}


# ------------------------------------------------------------------ CAN (python-can virtual bus)
class CanSensorBoard:
    """The board on a python-can virtual bus, in a thread; the bench opens ``url``."""

    _channels = itertools.count(1)

    def __init__(self, sensor_set: float, capabilities: int = CAP_GATES | CAP_SENSOR_SET):
        import can

        from protocol.can_mapping import CanReassembler

        channel = f"sensor-board-{os.getpid()}-{next(CanSensorBoard._channels)}"
        self.url = f"can:virtual:{channel}"
        self.logic = SensorBoardLogic(sensor_set, capabilities)
        self._can = can
        self._bus = can.Bus(interface="virtual", channel=channel)
        self._rx = CanReassembler()
        self._seq = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    @property
    def samples(self) -> list:
        return self.logic.samples

    def _send(self, msg) -> None:
        from protocol.can_mapping import DEFAULT_BASE_ID, can_pack

        frames = can_pack(msg, Role.CONTROLLER, DEFAULT_BASE_ID, self._seq)
        if len(frames) > 1:
            self._seq = (self._seq + 1) & 0x0F
        for arbitration_id, data in frames:
            self._bus.send(self._can.Message(arbitration_id=arbitration_id, data=data,
                                             is_extended_id=False))

    def _run(self) -> None:
        try:
            while not self._stop.is_set():
                frame = self._bus.recv(0.05)
                if frame is None:
                    continue
                got = self._rx.feed(frame.arbitration_id, frame.data)
                if got is None or got[1] != Role.BENCH:
                    continue
                if isinstance(got[0], Shutdown):
                    return
                for answer in self.logic.react(got[0]):
                    self._send(answer)
        finally:
            self._bus.shutdown()

    def __enter__(self) -> "CanSensorBoard":
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join(2.0)


# ------------------------------------------------------------------ exec: (its own process)
def exec_url(directory: Path, sensor_set: float, record: Path) -> str:
    """exec: on a launcher in ``directory`` that runs this file with this interpreter (the
    exec: link resolves symbolic links, which would take a virtual environment's python out of
    its environment)."""
    launcher = Path(directory) / "sensor_board.sh"
    launcher.write_text(f'#!/bin/sh\nexec "{sys.executable}" "{Path(__file__).resolve()}" "$@"\n')
    launcher.chmod(0o755)
    return f"exec:{launcher}?args=--sensor-set {float(sensor_set)!r} --record {record}"


def read_record(path: Path) -> list[dict]:
    """What an exec: board received (its --record file)."""
    if not Path(path).exists():
        return []
    return [json.loads(line) for line in Path(path).read_text().splitlines() if line]


def serve_stdio(logic: SensorBoardLogic, record: Path) -> None:
    from protocol.codec import FrameEncoder, StreamDecoder

    enc, dec = FrameEncoder(), StreamDecoder()
    with open(record, "w") as out:
        while True:
            ready, _, _ = select.select([0], [], [], 1.0)
            if not ready:
                continue
            data = os.read(0, 4096)
            if not data:
                return
            for msg in dec.feed(data):
                if isinstance(msg, Shutdown):
                    return
                for answer in logic.react(msg):
                    os.write(1, enc.encode(answer))
                if isinstance(msg, (Sample, SampleSensors)):
                    out.write(json.dumps(sample_record(msg)) + "\n")
                    out.flush()


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--sensor-set", type=float, required=True)
    parser.add_argument("--record", type=Path, required=True)
    args = parser.parse_args(argv)
    serve_stdio(SensorBoardLogic(args.sensor_set), args.record)
    return 0


if __name__ == "__main__":
    sys.exit(main())
