"""The Cortex-M4F firmware run in QEMU's mps2-an386 board, reachable as a serial link.

``QemuBoard`` builds the firmware when needed, starts ``qemu-system-arm`` with the
board's UART0 on a TCP socket on 127.0.0.1, and always stops QEMU again (its whole
process group), also when the body of the ``with`` raises::

    with QemuBoard() as board:
        link = open_link(board.link_url)      # "serial:socket://127.0.0.1:PORT"
        ...

QEMU is started with ``server=on,wait=on``: it listens before the guest runs and
starts the guest only when the first client connects, so no byte the firmware
sends is lost, and bytes the client sends first wait in the socket until the
firmware's UART takes them. ``-display none -monitor none`` and an explicit
``-serial`` keep QEMU's monitor off the line (``-nographic`` would multiplex it
there and swallow 0x01, the monitor's escape prefix).

The guest runs under ``-icount shift=7``: every instruction takes 2^7 ns of
virtual time, so its instruction stream is independent of host load, and a
SysTick tick (QEMU clocks SysTick at the board's 25 MHz) is shorter than an
instruction, so the firmware's SysTick measurement resolves single
instructions. QEMU itself still runs as fast as the host lets it.
"""
from __future__ import annotations

import ctypes
import os
import shutil
import signal
import socket
import subprocess
import threading
import time
import weakref
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parent.parent
BOARD_DIR = REPO_ROOT / "firmware_stub" / "boards" / "mps2_an386"
FIRMWARE_ELF = BOARD_DIR / "build" / "hil_stub.elf"
ECHO_ELF = BOARD_DIR / "build" / "echo.elf"

QEMU_BINARY = "qemu-system-arm"
CROSS_COMPILER = "arm-none-eabi-gcc"
ICOUNT_SHIFT = 7

# Debian packages that provide each tool, for error messages.
_PACKAGES = {
    QEMU_BINARY: "qemu-system-arm",
    CROSS_COMPILER: "gcc-arm-none-eabi libnewlib-arm-none-eabi",
    "make": "make",
}

_LISTENING_MARK = "waiting for connection on"
_build_lock = threading.Lock()


class _OutputCollector:
    """QEMU's stdout+stderr, read by a thread that must not hold the QemuBoard
    (else the board could never be garbage-collected and its finalizer never run)."""

    def __init__(self) -> None:
        self.lines: list[str] = []
        self.lock = threading.Lock()
        self.listening = threading.Event()

    def read(self, stream) -> None:
        for raw in iter(stream.readline, b""):
            line = raw.decode("utf-8", "replace")
            with self.lock:
                self.lines.append(line)
            if _LISTENING_MARK in line:
                self.listening.set()

    def text(self) -> str:
        with self.lock:
            return "".join(self.lines)


class QemuBoardError(RuntimeError):
    """QEMU or the firmware build could not be started, or QEMU died."""


def _require_tool(name: str) -> str:
    path = shutil.which(name)
    if path is None:
        package = _PACKAGES[name]
        raise QemuBoardError(
            f"{name} not found on PATH: install the Debian package(s) {package} with "
            f"'sudo apt-get update && sudo apt-get install -y {package}' "
            f"(scripts/bootstrap.sh does this when run as root)")
    return path


def build_firmware(elf_path: Path = FIRMWARE_ELF) -> Path:
    """Runs make for an ELF of the board directory (incremental: quick when up to date)."""
    elf_path = Path(elf_path).resolve()
    try:
        target = elf_path.relative_to(BOARD_DIR)
    except ValueError:
        raise QemuBoardError(f"{elf_path} is not built by {BOARD_DIR}/Makefile; build it yourself "
                             f"or pass build=False") from None
    _require_tool("make")
    _require_tool(CROSS_COMPILER)
    with _build_lock:
        proc = subprocess.run(["make", "-s", "-C", str(BOARD_DIR), str(target)],
                              capture_output=True, text=True)
    if proc.returncode != 0 or not elf_path.exists():
        raise QemuBoardError(f"building {target} with 'make -C {BOARD_DIR} {target}' failed "
                             f"(exit {proc.returncode}):\n{proc.stdout}{proc.stderr}")
    return elf_path


def _free_tcp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def _die_with_parent() -> None:
    """Runs in the child before exec: SIGKILL QEMU if the Python process dies
    without reaching __exit__ (e.g. it is itself SIGKILLed)."""
    pr_set_pdeathsig = 1
    libc = ctypes.CDLL(None, use_errno=True)
    libc.prctl(pr_set_pdeathsig, signal.SIGKILL, 0, 0, 0)


def _kill_group(proc: subprocess.Popen, grace_s: float) -> None:
    """SIGTERM then SIGKILL to QEMU's process group, and reap QEMU."""
    if proc.poll() is None:
        for sig, wait_s in ((signal.SIGTERM, grace_s), (signal.SIGKILL, 5.0)):
            try:
                os.killpg(proc.pid, sig)
            except ProcessLookupError:
                break
            try:
                proc.wait(timeout=wait_s)
                break
            except subprocess.TimeoutExpired:
                continue
    # QEMU is the group leader and the only member, but make sure nothing it
    # may have spawned survives it.
    try:
        os.killpg(proc.pid, signal.SIGKILL)
    except (ProcessLookupError, PermissionError):
        pass
    if proc.poll() is None:
        proc.wait()


class QemuBoard:
    """One QEMU mps2-an386 instance running the controller firmware.

    elf_path: firmware to run (default: the controller, firmware_stub/boards/mps2_an386/build/hil_stub.elf).
    build: run make for it first (only for ELFs of the board directory).
    icount_shift: QEMU -icount shift; None runs without icount.
    startup_timeout_s: how long QEMU may take to listen on its socket.
    extra_args: more QEMU arguments (e.g. ["-d", "guest_errors"]).
    """

    def __init__(self, elf_path: str | Path | None = None, build: bool = True,
                 icount_shift: int | None = ICOUNT_SHIFT, startup_timeout_s: float = 10.0,
                 extra_args: list[str] | None = None):
        self.elf_path = Path(elf_path) if elf_path is not None else FIRMWARE_ELF
        self.build = build
        self.icount_shift = icount_shift
        self.startup_timeout_s = startup_timeout_s
        self.extra_args = list(extra_args or [])
        self.port: int | None = None
        self._proc: subprocess.Popen | None = None
        self._output = _OutputCollector()
        self._reader: threading.Thread | None = None
        self._finalizer: weakref.finalize | None = None

    # -- context manager ------------------------------------------------------------
    def __enter__(self) -> "QemuBoard":
        self.start()
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        self.stop()

    # -- addresses ------------------------------------------------------------------
    @property
    def serial_url(self) -> str:
        """pyserial URL of the board's UART0: socket://127.0.0.1:PORT."""
        if self.port is None:
            raise QemuBoardError("QemuBoard is not started")
        return f"socket://127.0.0.1:{self.port}"

    @property
    def link_url(self) -> str:
        """The bench's link string for this board: serial:socket://127.0.0.1:PORT."""
        return "serial:" + self.serial_url

    @property
    def pid(self) -> int | None:
        return self._proc.pid if self._proc is not None else None

    @property
    def returncode(self) -> int | None:
        """QEMU's exit status once it has exited (the firmware's semihosting exit
        status: 0 after SHUTDOWN, 3 on a fault), None while it runs."""
        return self._proc.poll() if self._proc is not None else None

    def output(self) -> str:
        """Everything QEMU printed (stdout and stderr) so far."""
        return self._output.text()

    def command(self, port: int) -> list[str]:
        cmd = [QEMU_BINARY, "-M", "mps2-an386", "-cpu", "cortex-m4",
               "-display", "none", "-monitor", "none", "-nodefaults",
               "-serial", f"tcp:127.0.0.1:{port},server=on,wait=on,nodelay=on",
               # the firmware exits QEMU with a status on SHUTDOWN or a fault (SYS_EXIT only)
               "-semihosting-config", "enable=on,target=native",
               "-kernel", str(self.elf_path)]
        if self.icount_shift is not None:
            cmd[1:1] = ["-icount", f"shift={self.icount_shift}"]
        return cmd + self.extra_args

    # -- life cycle -----------------------------------------------------------------
    def start(self) -> None:
        if self._proc is not None:
            raise QemuBoardError("QemuBoard already started")
        _require_tool(QEMU_BINARY)
        if self.build:
            build_firmware(self.elf_path)
        if not self.elf_path.exists():
            raise QemuBoardError(f"firmware {self.elf_path} does not exist; build it with "
                                 f"'make -C {BOARD_DIR}'")
        try:
            # The port is free when probed but another process may take it before
            # QEMU binds: retry on a bind failure.
            for attempt in range(5):
                port = _free_tcp_port()
                if self._launch(port):
                    self.port = port
                    return
                if "Address already in use" not in self.output():
                    break
            raise QemuBoardError(f"QEMU did not start listening on 127.0.0.1 "
                                 f"(command: {' '.join(self.command(0))}):\n{self.output()}")
        except BaseException:
            self.stop()
            raise

    def _launch(self, port: int) -> bool:
        """Starts QEMU on `port`; True once it listens, False if it exited first."""
        self._stop_process()
        self._output = _OutputCollector()
        main_thread = threading.current_thread() is threading.main_thread()
        # PR_SET_PDEATHSIG fires when the *thread* that forked exits, so it is
        # only safe from the main thread; from other threads, cleanup relies on
        # stop() / the finalizer.
        self._proc = subprocess.Popen(
            self.command(port), stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT, start_new_session=True,
            preexec_fn=_die_with_parent if main_thread else None)
        self._finalizer = weakref.finalize(self, _kill_group, self._proc, 0.5)
        self._reader = threading.Thread(target=self._output.read, args=(self._proc.stdout,),
                                        name=f"qemu-output-{self._proc.pid}", daemon=True)
        self._reader.start()
        deadline = time.monotonic() + self.startup_timeout_s
        while time.monotonic() < deadline:
            if self._output.listening.wait(timeout=0.05):
                return True
            if self._proc.poll() is not None:
                self._reader.join(timeout=1.0)
                return False
        raise QemuBoardError(f"QEMU did not listen on 127.0.0.1:{port} within "
                             f"{self.startup_timeout_s} s:\n{self.output()}")

    def check_alive(self) -> None:
        """Raises QemuBoardError, with QEMU's output, if QEMU has exited."""
        if self._proc is None:
            raise QemuBoardError("QemuBoard is not started")
        code = self._proc.poll()
        if code is not None:
            raise QemuBoardError(f"QEMU exited with status {code}"
                                 f"{' (firmware fault)' if code == 3 else ''}:\n{self.output()}")

    def wait_exit(self, timeout_s: float) -> int | None:
        """Waits for QEMU to exit on its own (firmware SHUTDOWN); its status, or None on timeout."""
        if self._proc is None:
            return None
        try:
            return self._proc.wait(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            return None

    def _stop_process(self) -> None:
        if self._finalizer is not None:
            self._finalizer()  # runs _kill_group once
            self._finalizer = None
        if self._proc is not None and self._proc.stdout is not None:
            if self._reader is not None:
                self._reader.join(timeout=2.0)
            self._proc.stdout.close()
        self._reader = None

    def stop(self) -> int | None:
        """Stops QEMU (SIGTERM, then SIGKILL to its process group); returns its exit status."""
        self._stop_process()
        code = self._proc.returncode if self._proc is not None else None
        return code
