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

The guest runs under ``-icount shift=7``: virtual time advances 2^7 ns per
executed instruction, so the cost the firmware measures for a control step is
an instruction count that does not depend on host load; and a SysTick tick
(QEMU clocks SysTick at the board's 25 MHz of virtual time) is then shorter than
an instruction, so the SysTick measurement resolves single instructions
(firmware_stub/boards/mps2_an386/cycles.h). QEMU still runs as fast as the host
lets it.
"""
from __future__ import annotations

import os
import shutil
import signal
import socket
import subprocess
import threading
import time
import weakref
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[2]
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
    "arm-none-eabi-size": "binutils-arm-none-eabi",
    "make": "make",
}

# board_halt() statuses (vectors.c, main.c), as QEMU's exit status under semihosting.
EXIT_REASONS = {
    3: "firmware fault: HardFault, MemManage, BusFault, UsageFault or NMI",
    4: "firmware took an interrupt it has no handler for",
    5: "the app instance does not fit the RAM left between statics and stack",
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


class QemuToolMissing(QemuBoardError):
    """A program QEMU runs need (qemu-system-arm, the Arm toolchain) is not on this machine:
    the run cannot happen here, which is not a fault of the board or the bench."""


def _require_tool(name: str) -> str:
    path = shutil.which(name)
    if path is None:
        package = _PACKAGES[name]
        raise QemuToolMissing(
            f"{name} not found on PATH: install the Debian package(s) {package} with "
            f"'sudo apt-get update && sudo apt-get install -y {package}' "
            f"(scripts/bootstrap.sh --test does this when run as root)")
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


def _death_signal_wrapper() -> list[str]:
    """Command prefix that makes QEMU receive SIGKILL when its parent dies, so it
    cannot outlive a Python process killed before __exit__ (prctl PR_SET_PDEATHSIG,
    kept across exec). util-linux's setpriv does it between fork and exec, where
    running Python code (preexec_fn) could deadlock a threaded parent."""
    setpriv = shutil.which("setpriv")
    return [setpriv, "--pdeathsig", "KILL"] if setpriv else []


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
    def process(self) -> subprocess.Popen | None:
        """The QEMU process (e.g. for a liveness check); stop() still owns its end."""
        return self._proc

    @property
    def returncode(self) -> int | None:
        """QEMU's exit status once it has exited, None while it runs. The firmware
        exits through semihosting only when it halts: see EXIT_REASONS."""
        return self._proc.poll() if self._proc is not None else None

    def output(self) -> str:
        """Everything QEMU printed (stdout and stderr) so far."""
        return self._output.text()

    def command(self, port: int) -> list[str]:
        cmd = [QEMU_BINARY, "-M", "mps2-an386", "-cpu", "cortex-m4",
               "-display", "none", "-monitor", "none", "-nodefaults",
               "-serial", f"tcp:127.0.0.1:{port},server=on,wait=on,nodelay=on",
               # the firmware exits QEMU with a status when it halts (EXIT_REASONS); SYS_EXIT only
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
        # The parent-death signal fires when the *thread* that forked exits, so
        # it is only used from the main thread; from other threads, cleanup
        # relies on stop() and the finalizer.
        main_thread = threading.current_thread() is threading.main_thread()
        prefix = _death_signal_wrapper() if main_thread else []
        self._proc = subprocess.Popen(
            prefix + self.command(port), stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT, start_new_session=True)
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
            reason = EXIT_REASONS.get(code)
            raise QemuBoardError(f"QEMU exited with status {code}{f' ({reason})' if reason else ''}:\n"
                                 f"{self.output()}")

    def wait_exit(self, timeout_s: float) -> int | None:
        """Waits for QEMU to exit on its own (a firmware that halts); its status, or None on timeout."""
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


# -- on-target cost of the control step --------------------------------------------------
def firmware_size(elf_path: str | Path = FIRMWARE_ELF) -> dict[str, int]:
    """Flash (text + initialised data) and RAM (data + bss, stack and app instance
    excluded) of a firmware ELF, from arm-none-eabi-size."""
    _require_tool("arm-none-eabi-size")
    out = subprocess.run(["arm-none-eabi-size", str(elf_path)], capture_output=True, text=True,
                         check=True).stdout.splitlines()[1].split()
    text, data, bss = (int(v) for v in out[:3])
    return {"text_bytes": text, "data_bytes": data, "bss_bytes": bss,
            "flash_bytes": text + data, "static_ram_bytes": data + bss}


def rotating_samples(count: int, electrical_hz: float = 50.0, period_s: float = 50e-6):
    """SAMPLEs of balanced phase currents rotating at electrical_hz, an encoder turning
    with them and a steady DC link: synthetic, open-loop inputs on which every estimator
    and all six sectors do work, for measuring and comparing the firmware."""
    import math

    from protocol.messages import Sample

    for k in range(count):
        theta = 2.0 * math.pi * electrical_hz * k * period_s
        yield Sample(k, 2048 + int(400 * math.cos(theta)),
                     2048 + int(400 * math.cos(theta - 2.0 * math.pi / 3.0)),
                     2900, int(electrical_hz * k * period_s * 4096) & 0xFFFF, 0)


def measure_control_step(samples: int = 400, icount_shift: int = ICOUNT_SHIFT,
                         telemetry_divider: int = 10) -> dict:
    """Cycles of ctl_step on the target (instructions under QEMU icount), as the firmware
    itself reports them through HIL_PARAM_CONTROL_STEP_CYCLES after every SAMPLE, for each
    speed source, split into the steps that also fill a TELEMETRY (every
    telemetry_divider-th) and those that do not. The first step (cold state) is left out."""
    import statistics

    from protocol.links import open_link
    from protocol.messages import (CMD_ENABLE, PROTOCOL_VERSION, Command, Gates, Hello, ParamGet, ParamId,
                                   ParamSet, ParamValue, Role, SpeedSource)

    def exchange(link, msg, answer_type):
        link.send(msg)
        while True:
            reply = link.recv(5.0)
            if reply is None:
                raise QemuBoardError(f"the firmware did not answer {msg} within 5 s")
            if isinstance(reply, answer_type):
                return reply

    def stats(values: list[int]) -> dict:
        return {"median": int(statistics.median(values)), "min": min(values), "max": max(values),
                "steps": len(values)}

    result: dict = {"icount_shift": icount_shift, "telemetry_divider": telemetry_divider, "modes": {}}
    with QemuBoard(icount_shift=icount_shift) as board, open_link(board.link_url) as link:
        result["hello_name"] = exchange(link, Hello(PROTOCOL_VERSION, Role.BENCH, 0, 50_000, name=b"measure"),
                                        Hello).name_str
        exchange(link, ParamSet(ParamId.TELEMETRY_DIVIDER, float(telemetry_divider)), ParamValue)
        for source in SpeedSource:
            # STATUS answers only a change of state: do not wait for one when switching source
            link.send(Command(CMD_ENABLE, source, 100.0, 0.0, 0.0))
            plain, with_telemetry = [], []
            for sample in rotating_samples(samples):
                exchange(link, sample, Gates)
                cycles = int(exchange(link, ParamGet(ParamId.CONTROL_STEP_CYCLES), ParamValue).value)
                if sample.period == 0:
                    continue
                (with_telemetry if sample.period % telemetry_divider == 0 else plain).append(cycles)
            result["modes"][source.name.lower()] = {"step": stats(plain),
                                                    "step_with_telemetry": stats(with_telemetry)}
    result.update(firmware_size(FIRMWARE_ELF))
    return result


def main() -> None:
    """python -m hil.links.qemu: prints the on-target step cost and the firmware size."""
    r = measure_control_step()
    print(f"firmware: {r['hello_name']} (QEMU mps2-an386, -icount shift={r['icount_shift']})")
    print("instructions per ctl_step, median (min-max) over 399 steps:")
    for mode, c in r["modes"].items():
        a, b = c["step"], c["step_with_telemetry"]
        print(f"  speed source {mode:12s}: {a['median']} ({a['min']}-{a['max']}); "
              f"with TELEMETRY (1 in {r['telemetry_divider']}): {b['median']} ({b['min']}-{b['max']})")
    print(f"flash {r['flash_bytes']} B (text {r['text_bytes']}, data {r['data_bytes']}), "
          f"static RAM {r['static_ram_bytes']} B (data + bss)")


if __name__ == "__main__":
    main()
