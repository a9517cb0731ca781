"""One string names the board the bench talks to (python-can's ``interface=`` idea).

========================  ==================================================
``stub``                   the stub firmware in-process (shared library); CI default
``stub-pty``               ``hil-stub`` process on a pseudo-terminal, through pyserial
``stub-can``               ``hil-stub`` process speaking SLCAN on a pseudo-terminal,
                           through python-can's own ``slcan`` interface
``qemu``                   the Cortex-M4F firmware in QEMU (mps2-an386), UART on TCP
``serial:PORT[?baud=N]``   a real board on any pyserial port or URL
``can:IFACE:CH[?...]``     a real board through any python-can interface
========================  ==================================================

A BoardConnection owns the link and whatever process plays the board, and
``close`` stops both, whatever happened before.
"""
from __future__ import annotations

import os
import subprocess
import termios
import tty
from dataclasses import dataclass, field
from typing import Any, Callable

from protocol.links import LinkError, open_link
from protocol.messages import Role

from hil.links.stub_library import EXECUTABLE_PATH, StubLibraryLink, ensure_built

LINK_CHOICES = ("stub", "stub-pty", "stub-can", "qemu", "serial:PORT[?baud=N]",
                "can:INTERFACE:CHANNEL[?bitrate=N]")


@dataclass
class BoardConnection:
    spec: str
    link: Any
    # Seconds to wait for the board's HELLO: a spawned process or an emulator needs longer.
    hello_timeout_s: float = 2.0
    # Wall-clock wait for a GATES answer before a period counts as missed.
    answer_timeout_s: float = 0.25
    _cleanups: list[Callable[[], None]] = field(default_factory=list)
    process: subprocess.Popen | None = None

    def board_alive(self) -> bool:
        return self.process is None or self.process.poll() is None

    def board_exit_status(self) -> int | None:
        return None if self.process is None else self.process.poll()

    def close(self) -> None:
        errors = []
        try:
            self.link.close()
        except Exception as exc:  # noqa: BLE001 - teardown must run every step
            errors.append(exc)
        for cleanup in reversed(self._cleanups):
            try:
                cleanup()
            except Exception as exc:  # noqa: BLE001
                errors.append(exc)
        self._cleanups.clear()
        if errors:
            raise errors[0]


def _stop_process(proc: subprocess.Popen, grace_s: float = 1.0) -> None:
    if proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(grace_s)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(grace_s)


def _pty_pair() -> tuple[int, int, str]:
    """A pseudo-terminal whose slave is raw before anyone writes (no echo of the board's bytes).

    The slave stays open until the bench's link has opened it too: a process reading a
    master whose slave nobody holds gets EIO and would take it for a hang-up."""
    master, slave = os.openpty()
    tty.setraw(slave, termios.TCSANOW)
    return master, slave, os.ttyname(slave)


def _spawn_stub(args: list[str], master_fd: int) -> subprocess.Popen:
    ensure_built()
    return subprocess.Popen([str(EXECUTABLE_PATH), *args], stdin=master_fd, stdout=master_fd,
                            stderr=subprocess.PIPE, close_fds=True, start_new_session=True)


def connect(spec: str) -> BoardConnection:
    """Opens the board named by ``spec``; raises LinkError naming what was wrong."""
    if spec == "stub":
        return BoardConnection(spec, StubLibraryLink(), hello_timeout_s=0.5, answer_timeout_s=0.0)
    if spec in ("stub-pty", "stub-can"):
        master, slave, slave_path = _pty_pair()
        mode = ["--stdio"] if spec == "stub-pty" else ["--slcan-stdio"]
        try:
            proc = _spawn_stub(mode, master)
        finally:
            os.close(master)  # the child holds it now
        try:
            if spec == "stub-pty":
                link = open_link(f"serial:{slave_path}?baud=2000000")
            else:
                link = open_link(f"can:slcan:{slave_path}?bitrate=1000000", role=Role.BENCH,
                                 sleep_after_open=0)
        except Exception:
            _stop_process(proc)
            raise
        finally:
            os.close(slave)
        conn = BoardConnection(spec, link, hello_timeout_s=3.0, answer_timeout_s=0.5, process=proc)
        conn._cleanups.append(lambda: _stop_process(proc))
        return conn
    if spec == "qemu":
        from hil.links.qemu import QemuBoard

        board = QemuBoard()
        board.__enter__()
        try:
            link = open_link(f"serial:{board.serial_url}")
        except Exception:
            board.__exit__(None, None, None)
            raise
        conn = BoardConnection(spec, link, hello_timeout_s=10.0, answer_timeout_s=2.0,
                               process=board.process)
        conn._cleanups.append(lambda: board.__exit__(None, None, None))
        return conn
    if spec.startswith("serial:") or spec.startswith("can:"):
        kwargs = {"role": Role.BENCH} if spec.startswith("can:") else {}
        return BoardConnection(spec, open_link(spec, **kwargs), hello_timeout_s=3.0,
                               answer_timeout_s=0.5)
    raise LinkError(f"unknown link '{spec}'; expected one of: {', '.join(LINK_CHOICES)}")
