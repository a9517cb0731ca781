"""One string names the board the bench talks to (python-can's ``interface=`` idea, pyserial's
``serial_for_url``): ``connect(spec)`` is the one registry of link types.

=======================================  ==========================================================
``exec:PATH[?args=...&transport=T]``      any executable speaking the protocol on stdin/stdout,
                                           run on a pseudo-terminal; T = serial (default) or slcan
``lib:PATH.so[?args=...&transport=T]``    a firmware built as a shared library with the firmware
                                           ABI of protocol/c/hil_fw_abi.h, in-process, a private
                                           copy per session; T = serial (default) or can
``qemu:IMAGE.elf[?machine=M&cpu=C]``      any Cortex-M image following docs/porting.md in QEMU
                                           (default mps2-an386, cortex-m4; -icount shift=7)
``serial:PORT[?baud=N]``                  a real board on any pyserial port or URL
``can:IFACE:CH[?bitrate=N&...]``          a real board through any python-can interface
``stub``                                  ``lib:`` on the stub's firmware_stub/build/libhilstub.so
``stub-pty``                              ``exec:`` on the stub's ``hil-stub --stdio``
``stub-can``                              ``exec:`` on ``hil-stub --slcan-stdio``, transport slcan
``qemu``                                  ``qemu:`` on the stub's Cortex-M4F image
=======================================  ==========================================================

Third-party link types are found through the entry-point group ``hil.links``: an entry point
named ``NAME`` makes ``NAME:REST`` a link string. It loads to a callable ``factory(rest, spec)``
that returns a ``BoardConnection`` or a ``protocol.links.Link`` (wrapped in one). Built-in names
win over an entry point of the same name.

A BoardConnection owns the link and whatever process plays the board; ``close`` stops both,
whatever happened before, and ``report()`` says how the board process ended (exit status and
its last stderr lines) for every error message.
"""
from __future__ import annotations

# subprocess, threading, termios, tty and shlex: imported by the functions that start a board
# process; the in-process stub (every plan's default link) needs none of them.
import os
from collections import deque
from dataclasses import field
from pathlib import Path
from typing import Any, Callable
from urllib.parse import parse_qsl

from configfile.dataclass_methods import dataclass
from protocol.links import Link, LinkError, open_link
from protocol.messages import Role

from hil.links.stub_library import EXECUTABLE_PATH, LIBRARY_PATH, ensure_built

ENTRY_POINT_GROUP = "hil.links"

LINK_CHOICES = ("stub", "stub-pty", "stub-can", "qemu", "exec:PATH[?args=...&transport=serial|slcan]",
                "lib:PATH.so[?args=...&transport=serial|can]", "qemu:IMAGE.elf[?machine=mps2-an386]", "serial:PORT[?baud=N]",
                "can:INTERFACE:CHANNEL[?bitrate=N]")

STDERR_LINES = 10


class LinkUnavailable(LinkError):
    """The link needs a program this machine does not have (QEMU, the Arm toolchain): a plan
    on it is SKIPPED with this reason, not an ERROR of the board or the bench."""


@dataclass
class BoardConnection:
    spec: str
    link: Any
    # Waits a link that starts the board itself may raise (SPEC 2.8); None: the session policy's.
    hello_wait_s: float | None = None
    answer_wait_min_s: float | None = None
    process: Any = None                       # subprocess.Popen of the board, if any
    wire: Any = None                          # hil.links.wire.WireModel from `wire=`, if any
    _cleanups: list[Callable[[], None]] = field(default_factory=list)
    _output: Callable[[], list[str]] | None = None   # the board process's last output lines

    def board_alive(self) -> bool:
        return self.process is None or self.process.poll() is None

    def board_exit_status(self) -> int | None:
        return None if self.process is None else self.process.poll()

    def output_tail(self) -> list[str]:
        return list(self._output()) if self._output is not None else []

    def report(self) -> str:
        """'' while the board runs (or has no process); else its exit status and last stderr lines."""
        if self.process is None:
            return ""
        status = self.process.poll()
        if status is None:
            return ""
        text = f"the board process exited with status {status}"
        tail = [line.rstrip() for line in self.output_tail() if line.strip()]
        if tail:
            text += "; its last stderr lines:\n    " + "\n    ".join(tail[-STDERR_LINES:])
        return text

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
    import subprocess

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
    import termios
    import tty

    master, slave = os.openpty()
    tty.setraw(slave, termios.TCSANOW)
    return master, slave, os.ttyname(slave)


class _StderrTail:
    """The last lines a board process wrote on stderr, read by a daemon thread."""

    def __init__(self, stream, keep: int = 50) -> None:
        import threading

        self.lines: deque[str] = deque(maxlen=keep)
        self._lock = threading.Lock()
        self._thread = threading.Thread(target=self._read, args=(stream,), daemon=True)
        self._thread.start()

    def _read(self, stream) -> None:
        try:
            for raw in iter(stream.readline, b""):
                with self._lock:
                    self.lines.append(raw.decode("utf-8", "replace"))
        except (OSError, ValueError):
            pass
        finally:
            stream.close()              # the board closed its end: ours is done too

    def __call__(self) -> list[str]:
        self._thread.join(0.2)          # the process has exited: let its last lines arrive
        with self._lock:
            return list(self.lines)


def _query(spec: str, rest: str, allowed: tuple[str, ...]) -> tuple[str, dict[str, str]]:
    """PATH?key=value&... -> (PATH, options); every link type's options go through here.
    An unknown or repeated option is refused, naming it (and the nearest known one)."""
    target, _, query = rest.partition("?")
    pairs = parse_qsl(query, keep_blank_values=True)
    options = dict(pairs)
    unknown = sorted(set(options) - set(allowed))
    if unknown:
        from difflib import get_close_matches

        hints = [f"'{name}'" for u in unknown for name in get_close_matches(u, allowed, n=1)]
        hint = f" (did you mean {', '.join(hints)}?)" if hints else ""
        raise LinkError(f"link '{spec}': unknown option(s) {', '.join(unknown)}{hint}; "
                        f"expected {', '.join(allowed) or 'none'}")
    if len(options) != len(pairs):
        twice = sorted({k for k, _ in pairs if [p for p, _ in pairs].count(k) > 1})
        raise LinkError(f"link '{spec}': option(s) {', '.join(twice)} given more than once")
    if not target:
        raise LinkError(f"link '{spec}': no path given")
    return target, options


def _args_option(spec: str, options: dict[str, str]) -> list[str]:
    """The ``args=`` option split like a shell's words (exec: and lib: alike)."""
    import shlex

    try:
        return shlex.split(options.get("args", ""))
    except ValueError as exc:
        raise LinkError(f"link '{spec}': args: {exc}") from None


# ------------------------------------------------------------------ built-in link types

def _exec_link(rest: str, spec: str) -> BoardConnection:
    target, options = _query(spec, rest, ("args", "transport"))
    transport = options.get("transport", "serial")
    if transport not in ("serial", "slcan"):
        raise LinkError(f"link '{spec}': transport '{transport}'; expected serial or slcan")
    path = Path(target)
    if not path.is_file():
        raise LinkError(f"link '{spec}': executable '{path}' does not exist")
    if not os.access(path, os.X_OK):
        raise LinkError(f"link '{spec}': '{path}' is not executable (chmod +x?)")
    args = _args_option(spec, options)
    return spawn_on_pty(spec, [str(path.resolve()), *args], transport)


def spawn_on_pty(spec: str, argv: list[str], transport: str = "serial") -> BoardConnection:
    """Starts ``argv`` with stdin/stdout on a pseudo-terminal's master; the bench opens the slave."""
    import subprocess

    master, slave, slave_path = _pty_pair()
    try:
        proc = subprocess.Popen(argv, stdin=master, stdout=master, stderr=subprocess.PIPE,
                                close_fds=True, start_new_session=True)
    except OSError as exc:
        os.close(master)
        os.close(slave)
        raise LinkError(f"link '{spec}': cannot start {argv[0]}: {exc}") from exc
    # The bench keeps its copy of the master until the slave is open: a board that exits at
    # once would otherwise take the pseudo-terminal (and /dev/pts/N) with it, and the bench
    # would report a missing port instead of the board's exit status.
    tail = _StderrTail(proc.stderr)
    try:
        if transport == "serial":
            link = open_link(f"serial:{slave_path}?baud=2000000")
        else:
            link = open_link(f"can:slcan:{slave_path}?bitrate=1000000", role=Role.BENCH,
                             sleep_after_open=0)
    except Exception:
        _stop_process(proc)
        raise
    finally:
        os.close(slave)
        os.close(master)  # the child holds it now
    conn = BoardConnection(spec, link, process=proc, _output=tail)
    conn._cleanups.append(lambda: _stop_process(proc))
    return conn


def _lib_link(rest: str, spec: str) -> BoardConnection:
    from hil.links.firmware_library import open_firmware_library

    target, options = _query(spec, rest, ("args", "transport"))
    transport = options.get("transport", "serial")
    if transport not in ("serial", "can"):
        raise LinkError(f"link '{spec}': transport '{transport}'; expected serial or can")
    link = open_firmware_library(target, transport=transport, url=spec,
                                 args=_args_option(spec, options))
    # In-process: the firmware answers within the call, so every wait is 0 (SPEC 2.8).
    return BoardConnection(spec, link, hello_wait_s=0.0, answer_wait_min_s=0.0)


def _stub_link(spec: str) -> BoardConnection:
    from hil.links.stub_library import StubLibraryLink

    return BoardConnection(spec, StubLibraryLink(), hello_wait_s=0.0, answer_wait_min_s=0.0)


def _qemu_link(rest: str, spec: str, build: bool = False) -> BoardConnection:
    from hil.links.qemu import QemuBoard, QemuBoardError, QemuToolMissing

    if rest:
        target, options = _query(spec, rest, ("machine", "cpu"))
        elf = Path(target)
        if not elf.is_file():
            raise LinkError(f"link '{spec}': image '{elf}' does not exist")
    else:
        elf, options = None, {}
    board = QemuBoard(elf, build=build)
    machine = options.get("machine", "mps2-an386")
    cpu = options.get("cpu", "cortex-m4" if machine == "mps2-an386" else None)
    base_command = board.command

    def command(port: int) -> list[str]:
        cmd = base_command(port)
        cmd[cmd.index("-M") + 1] = machine
        at = cmd.index("-cpu")
        if cpu is None:
            del cmd[at:at + 2]
        else:
            cmd[at + 1] = cpu
        return cmd

    board.command = command
    try:
        board.start()
    except QemuToolMissing as exc:
        raise LinkUnavailable(f"link '{spec}': {exc}") from exc
    except (QemuBoardError, OSError) as exc:
        raise LinkError(f"link '{spec}': {exc}") from exc
    try:
        link = open_link(f"serial:{board.serial_url}")
    except Exception:
        board.stop()
        raise
    # An emulator starting up and running under -icount may take longer (SPEC 2.8).
    conn = BoardConnection(spec, link, hello_wait_s=10.0, answer_wait_min_s=2.0,
                           process=board.process, _output=lambda: board.output().splitlines())
    conn._cleanups.append(board.stop)
    return conn


def _serial_link(rest: str, spec: str) -> BoardConnection:
    return BoardConnection(spec, open_link(spec))


def _can_link(rest: str, spec: str) -> BoardConnection:
    return BoardConnection(spec, open_link(spec, role=Role.BENCH))


BUILTIN_TYPES: dict[str, Callable[[str, str], BoardConnection]] = {
    "exec": _exec_link, "lib": _lib_link, "qemu": _qemu_link,
    "serial": _serial_link, "can": _can_link,
}


def _alias(spec: str) -> BoardConnection | None:
    if spec == "stub":
        return _stub_link(spec)
    if spec in ("stub-pty", "stub-can"):
        ensure_built()
        mode, transport = (("--stdio", "serial") if spec == "stub-pty"
                           else ("--slcan-stdio", "slcan"))
        return spawn_on_pty(spec, [str(EXECUTABLE_PATH), mode], transport)
    if spec == "qemu":
        return _qemu_link("", spec, build=True)
    return None


# The options each built-in type takes, and the values of its `transport` (None: no transport).
_OPTIONS: dict[str, tuple[tuple[str, ...], tuple[str, ...] | None]] = {
    "exec": (("args", "transport"), ("serial", "slcan")),
    "lib": (("args", "transport"), ("serial", "can")),
    "qemu": (("machine", "cpu"), None),
}


def parse_link(spec: str, plugin_types: tuple[str, ...] = ()) -> tuple[str, str, dict[str, str]]:
    """(type, target, options) of a link string, checked as connect() checks it but without
    opening anything (no file, port or program needs to exist): LinkError names what is wrong.
    plugin_types: entry-point type names to accept besides the installed ones.
    The docs' examples are parsed with it (tests/test_doc_examples.py)."""
    spec, _wire = split_wire(spec)            # any link takes wire=NAME (hil/links/wire.py)
    if spec in ("stub", "stub-pty", "stub-can", "qemu"):
        return spec, "", {}
    scheme, sep, rest = spec.partition(":")
    if sep and scheme in _OPTIONS:
        allowed, transports = _OPTIONS[scheme]
        target, options = _query(spec, rest, allowed)
        if transports is not None and options.get("transport", transports[0]) not in transports:
            raise LinkError(f"link '{spec}': transport '{options['transport']}'; expected "
                            f"{' or '.join(transports)}")
        if "args" in options:
            _args_option(spec, options)
        return scheme, target, options
    if sep and scheme == "serial":
        target, _, query = rest.partition("?")
        options = dict(parse_qsl(query, keep_blank_values=True))
        if not target:
            raise LinkError(f"link '{spec}': expected serial:PORT[?baud=N]")
        if "baud" in options and not options["baud"].isdigit():
            raise LinkError(f"link '{spec}': baud '{options['baud']}' is not an integer")
        return scheme, target, options
    if sep and scheme == "can":
        head, _, query = rest.partition("?")
        interface, _, channel = head.partition(":")
        if not interface:
            raise LinkError(f"link '{spec}': expected can:INTERFACE:CHANNEL[?bitrate=N]")
        return scheme, head, dict(parse_qsl(query, keep_blank_values=True))
    if sep and (scheme in plugin_types or scheme in entry_point_types()):
        return scheme, rest, {}
    if ("/" in spec and not sep) or "://" in spec:
        return "serial", spec, {}
    raise LinkError(f"unknown link '{spec}'; expected one of: {', '.join(LINK_CHOICES)}"
                    + _plugins_hint())


def entry_point_types() -> dict[str, Any]:
    """Third-party link types: the ``hil.links`` entry points by name (not loaded yet)."""
    from importlib.metadata import entry_points

    return {ep.name: ep for ep in entry_points(group=ENTRY_POINT_GROUP)}


def link_types() -> list[str]:
    """Every link type name: the built-ins, their stub aliases and the entry points."""
    return ["stub", "stub-pty", "stub-can", "qemu", *BUILTIN_TYPES,
            *sorted(set(entry_point_types()) - set(BUILTIN_TYPES))]


def split_wire(spec: str):
    """(the link string without its ``wire=`` option, the WireModel it names or None): any
    link type takes ``wire=NAME`` (hil/links/wire.py, docs/adapters.md)."""
    head, sep, query = spec.partition("?")
    if not sep:
        return spec, None
    parts = query.split("&")
    wires = [p[len("wire="):] for p in parts if p.startswith("wire=")]
    if not wires:
        return spec, None
    if len(wires) > 1:
        raise LinkError(f"link '{spec}': option(s) wire given more than once")
    from hil.links.wire import parse_wire

    rest = [p for p in parts if not p.startswith("wire=")]
    baud = next((p.partition("=")[2] for p in rest if p.startswith(("baud=", "baudrate="))), "")
    try:
        model = parse_wire(wires[0], int(baud) if baud.isdigit() else None)
    except ValueError as exc:
        raise LinkError(f"link '{spec}': {exc}") from None
    return head + ("?" + "&".join(rest) if rest else ""), model


def connect(spec: str) -> BoardConnection:
    """Opens the board named by ``spec``; raises LinkError naming what was wrong. A ``wire=``
    option (any link type) is taken off and set as the connection's ``wire``."""
    spec, wire = split_wire(spec)
    conn = _connect(spec)
    conn.wire = wire
    return conn


def _connect(spec: str) -> BoardConnection:
    conn = _alias(spec)
    if conn is not None:
        return conn
    scheme, sep, rest = spec.partition(":")
    if sep and scheme in BUILTIN_TYPES:
        return BUILTIN_TYPES[scheme](rest, spec)
    if sep:
        found = entry_point_types().get(scheme)
        if found is not None:
            try:
                factory = found.load()
            except Exception as exc:  # noqa: BLE001 - a broken plug-in is named, not raised raw
                raise LinkError(f"link '{spec}': link type '{scheme}' (entry point {found.value} "
                                f"in group {ENTRY_POINT_GROUP}) cannot be loaded: {exc}") from exc
            made = factory(rest, spec)
            if isinstance(made, BoardConnection):
                return made
            if isinstance(made, Link) or (hasattr(made, "send") and hasattr(made, "recv")):
                return BoardConnection(spec, made)
            raise LinkError(f"link '{spec}': link type '{scheme}' returned {type(made).__name__}, "
                            "not a BoardConnection or a Link")
    if ("/" in spec and not sep) or "://" in spec:
        # A bare path: pyserial's serial_for_url convention (a device or a URL).
        return BoardConnection(spec, open_link(spec))
    raise LinkError(f"unknown link '{spec}'; expected one of: {', '.join(LINK_CHOICES)}"
                    + _plugins_hint())


def check_link(spec: str) -> None:
    """The link string names a kind of link this bench knows (an alias, a built-in or an
    entry-point type, or a bare device path or URL), without opening anything; LinkError
    with a did-you-mean otherwise (a typo in --link is said once, before any plan runs)."""
    if spec in _ALIASES:
        return
    scheme, sep, rest = spec.partition(":")
    if sep and scheme in _FILE_OPTIONS:
        # the file a link runs or loads, and its options: checked here as connect() would
        target, _options = _query(spec, rest, _FILE_OPTIONS[scheme])
        if not Path(target).is_file():
            raise LinkError(f"link '{spec}': file '{target}' does not exist")
        return
    if sep and (scheme in BUILTIN_TYPES or scheme in entry_point_types()):
        return
    if ("/" in spec and not sep) or "://" in spec:
        return
    import difflib

    names = [*_ALIASES, *(f"{t}:" for t in BUILTIN_TYPES),
             *(f"{t}:" for t in sorted(set(entry_point_types()) - set(BUILTIN_TYPES)))]
    word = f"{scheme}:" if sep else spec
    close = difflib.get_close_matches(word, names, n=1, cutoff=0.6)
    hint = f" (did you mean '{close[0]}'?)" if close else ""
    raise LinkError(f"unknown link '{spec}'{hint}; expected one of: {', '.join(LINK_CHOICES)}"
                    + _plugins_hint())


_ALIASES = ("stub", "stub-pty", "stub-can", "qemu")
#: link types naming a file (an executable, a library, an image) -> the options they take
_FILE_OPTIONS = {"exec": ("args", "transport"), "lib": ("args", "transport"),
                 "qemu": ("machine", "cpu")}


def _plugins_hint() -> str:
    extra = sorted(set(entry_point_types()) - set(BUILTIN_TYPES))
    return f"; link types from entry points ({ENTRY_POINT_GROUP}): {', '.join(extra)}" if extra else ""
