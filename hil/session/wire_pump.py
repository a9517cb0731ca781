"""A modelled wire in real time: frames really held until their modelled arrival.

The link tap hands every frame out to ``send`` and takes what it decodes from ``recv``; in
between, one thread owns the link: it writes each frame out when the model says it reaches
the board and reads what the board sends as it comes, stamping the moment, and hands it to
the tap's decoder when the model says it reaches the bench (hil.links.wire.WireModel). A
thread, because the real-time loop sleeps most of each period: a frame released only at the
loop's next poll would be a period late. Each line carries one frame after another (a frame
cannot end before the one ahead of it plus its own bytes).

Only this thread touches the link after the first frame; the tap's decoder and queue are
used under ``lock`` (the tap's tick() takes it too). An error of the link is raised by the
next send or recv, as the link would have raised it.
"""
from __future__ import annotations

import os
import select
import threading
import time
from collections import deque

IDLE_WAIT_S = 0.05        # the thread's longest sleep with nothing held (it is woken on send)


class WirePump:
    def __init__(self, tap, wire) -> None:
        self.tap = tap
        self.wire = wire
        self.lock = threading.RLock()
        self.arrived = threading.Condition(self.lock)
        self.held = {"out": deque(), "in": deque()}      # (due monotonic s, bytes)
        self.line_free = {"out": 0.0, "in": 0.0}         # when each line is free again
        self.error: BaseException | None = None
        self._stop = False
        self._thread: threading.Thread | None = None
        self._wake_r, self._wake_w = os.pipe()
        os.set_blocking(self._wake_r, False)

    # -------------------------------------------------------------- the caller's side
    def send(self, frame: bytes) -> None:
        if self.error is not None:
            raise self.error
        with self.lock:
            self._queue("out", frame, time.monotonic())
        if self._thread is None:
            self._thread = threading.Thread(target=self._run, name="wire-pump", daemon=True)
            self._thread.start()
        os.write(self._wake_w, b"w")

    def recv(self, inbox: deque, timeout_s: float | None):
        with self.arrived:
            if not inbox and self.error is None and timeout_s != 0.0:
                self.arrived.wait_for(lambda: inbox or self.error is not None, timeout_s)
            if inbox:
                return inbox.popleft()
            if self.error is not None:
                raise self.error
            return None

    def close(self) -> None:
        self._stop = True
        if self._thread is not None:
            os.write(self._wake_w, b"s")
            self._thread.join(1.0)
        for fd in (self._wake_r, self._wake_w):
            try:
                os.close(fd)
            except OSError:
                pass

    # ------------------------------------------------------------------- the model
    def _queue(self, direction: str, data: bytes, now: float) -> None:
        wire = self.wire
        if direction == "out":
            due = wire.sample_arrival_s(now, len(data))
        else:
            due = wire.answer_arrival_s(now, len(data))
        due = max(due, self.line_free[direction] + wire._line(len(data)))
        self.line_free[direction] = due
        self.held[direction].append((due, data))

    def _next_due(self) -> float | None:
        dues = [q[0][0] for q in self.held.values() if q]
        return min(dues) if dues else None

    # ------------------------------------------------------------------ the thread
    def _run(self) -> None:
        link = self.tap.link
        descriptor = getattr(link, "descriptor", None)
        fd = descriptor() if descriptor is not None else None
        try:
            while not self._stop:
                self._release(link, time.monotonic())
                if fd is None:      # a library in this process answers within the call
                    self._read(link)
                with self.lock:
                    due = self._next_due()
                wait = IDLE_WAIT_S if due is None else max(0.0, due - time.monotonic())
                ready = select.select([self._wake_r] if fd is None else [fd, self._wake_r],
                                      [], [], wait)[0]
                if self._wake_r in ready:
                    self._drain_wake()
                if fd is not None and fd in ready and not self._stop:
                    self._read(link)
        except BaseException as exc:  # noqa: BLE001 - handed to the caller's next send/recv
            with self.arrived:
                self.error = exc
                self.arrived.notify_all()

    def _read(self, link) -> None:
        data = link.read_bytes(0.0)
        if data:
            with self.lock:
                self._queue("in", data, time.monotonic())

    def _drain_wake(self) -> None:
        try:
            os.read(self._wake_r, 4096)
        except BlockingIOError:
            pass

    def _release(self, link, now: float) -> None:
        out, back = self.held["out"], self.held["in"]
        while True:
            with self.lock:
                frame = out.popleft()[1] if out and out[0][0] <= now else None
            if frame is None:
                break
            link.send_bytes(frame)
        with self.arrived:
            delivered = False
            while back and back[0][0] <= now:
                self.tap._take_in(back.popleft()[1])
                delivered = True
            if delivered:
                self.arrived.notify_all()
