"""``hil serve``: the plant alone, driving whatever board is on the link, for interactive work.

The board gets its parameters and a disabled COMMAND at start; from then on the
bench is steered through the Modbus control port (run/stop, speed reference,
load torque, DC-link voltage, fault bits) or just watched in the log.
"""
from __future__ import annotations

import sys
import time

from hil.session.board_params import load_bench_profile

from hil.session.bench_session import BenchSession, SessionConfig


def parse_host_port(text: str, default_host: str = "127.0.0.1") -> tuple[str, int]:
    """'5020' or 'HOST:5020' -> (host, port); the default host is loopback (never all interfaces)."""
    host, _, port = text.rpartition(":")
    try:
        number = int(port)
    except ValueError:
        raise ValueError(f"Modbus port '{text}' is not [HOST:]PORT") from None
    if not 0 < number < 65536:
        raise ValueError(f"Modbus port {number} is out of range 1..65535")
    return host or default_host, number


def serve_command(args) -> int:
    from hil.ports.modbus import ControlMailbox, ModbusPort
    from hil.control_inputs import ControlLimits

    profile = load_bench_profile(args.profile)
    board = None
    if getattr(args, "board", None) is not None:
        from hil.boards import load_board

        board = load_board(args.board)
    # the one range check of every control input, from the profile (hil/control_inputs.py)
    limits = ControlLimits.from_profile(profile)
    limits.speed_ref_rpm(args.speed_rpm, "--speed-rpm")
    config = SessionConfig(link=args.link, mode=args.mode, log_path=args.log,
                           log_compression=args.log_compression, board=board,
                           profile_label=str(args.profile) if args.profile else "paper")
    mailbox = ControlMailbox(load_torque_nm=profile.load.torque_nm,
                             dc_link_voltage_v=profile.dc_link.source_voltage_v, run=args.enable,
                             speed_ref_rpm=args.speed_rpm)
    port = None
    if args.modbus and args.modbus != "off":
        host, number = parse_host_port(args.modbus)
        # A Modbus request holds the interpreter for 0.1-0.3 ms: in real time the port
        # runs in its own process so that it cannot stall a period.
        port = ModbusPort(mailbox, host=host, port=number, limits=limits,
                          isolation="process" if args.mode == "realtime" else "thread")
    chunk = max(1, round(0.01 / profile.control_period_s))  # 10 ms of simulated time
    total = None if args.duration is None else round(args.duration / profile.control_period_s)
    live = None
    pace = getattr(args, "pace", "fast")
    if getattr(args, "live", None):
        from hil.live.gate import FOXGLOVE_ORIGINS
        from hil.live import LiveStream, parse_live_address

        live_host, live_port = parse_live_address(args.live)
        live = LiveStream(live_host, live_port, period_s=profile.control_period_s,
                          rate_hz=args.live_rate_hz, mode=args.mode, pace=pace,
                          origins=FOXGLOVE_ORIGINS + tuple(getattr(args, "live_origin", None) or ()))
        # viewers' parameters take the Modbus port's path into the session
        live.attach_mailbox(mailbox, limits)
    try:
        return _serve(args, profile, config, mailbox, port, live, chunk, total, pace)
    finally:
        if live is not None:
            live.close()


class Pacer:
    """How long `hil serve` sleeps after a chunk: "realtime" keeps simulated time from running
    ahead of the wall clock (counted from when the mode was last switched on, so a switch from
    "fast" does not stall the run while the clock catches up), "fast" never sleeps."""

    def __init__(self, mode: str, period_s: float):
        self.mode = mode
        self.period_s = period_s
        self._origin: tuple[float, int] | None = None   # (wall, periods) when pacing began

    def wait_s(self, ran: int, now: float) -> float:
        if self.mode != "realtime":
            self._origin = None
            return 0.0
        if self._origin is None:
            self._origin = (now, ran)
            return 0.0
        wall0, ran0 = self._origin
        return max(0.0, (ran - ran0) * self.period_s - (now - wall0))


class _StatusLine:
    """One line on a terminal, rewritten twice a second: speed, torque, DC link, faults, rate."""

    def __init__(self, session):
        from plant_rt import TRUTH_FIELDS

        self.session = session
        self.index = {name: i for i, name in enumerate(TRUTH_FIELDS)}
        self.last = (time.monotonic(), 0)

    def show(self, ran: int) -> None:
        now = time.monotonic()
        t0, n0 = self.last
        row = self.session.recorder.latest_row("truth")
        if now - t0 < 0.5 or row is None:
            return
        self.last = (now, ran)
        f = self.index
        faults = f"faults 0x{self.session.fault_bits:x}" if self.session.fault_bits else "no faults"
        board = f", board FAULTs {len(self.session.faults)}" if self.session.faults else ""
        print(f"\r{row[f['speed_rpm']]:8.1f} rpm {row[f['torque_nm']]:6.3f} N m "
              f"{row[f['v_dc']]:5.1f} V  {faults}{board}  {(ran - n0) / (now - t0):8.0f} periods/s ",
              end="", file=sys.stderr, flush=True)


#: `--log` at fast pace: a rate above this is worth a warning (a minute is then gigabytes)
LOG_WARN_BYTES_PER_S = 10e6
#: the log size the rate is measured over (a few 64 KiB chunks: milliseconds at fast pace)
LOG_MEASURE_BYTES = 256 * 1024


class LogRate:
    """How fast `--log` grows: bytes a period (measured on the file, whose chunks are written
    as they fill) times the periods run a wall second. Says once, early, when that is more than
    LOG_WARN_BYTES_PER_S, with the rate and how to lower it."""

    def __init__(self, path, period_s: float):
        self.path = path
        self.period_s = period_s
        self.warned = False

    def size(self) -> int:
        import os

        try:
            return os.path.getsize(self.path)
        except OSError:
            return 0

    def warning(self, ran: int, wall_s: float, pace: str) -> str | None:
        """The warning to print now, or None (once: later calls return None)."""
        if self.warned or pace != "fast" or ran <= 0 or wall_s <= 0:
            return None
        size = self.size()
        if size < LOG_MEASURE_BYTES:
            return None
        bytes_per_period = size / ran
        periods_per_s = ran / wall_s
        rate = bytes_per_period * periods_per_s
        if rate <= LOG_WARN_BYTES_PER_S:
            return None
        self.warned = True
        realtime = bytes_per_period / self.period_s
        return (f"hil serve: warning: --log {self.path} at --pace fast writes {rate / 1e6:.0f} MB "
                f"a second ({bytes_per_period:.0f} bytes a period, {periods_per_s:.0f} periods a "
                f"second): {rate * 60 / 1e9:.1f} GB a minute. To lower it: --pace realtime "
                f"({realtime / 1e6:.1f} MB a second), --duration SECONDS to stop early, "
                f"--log-compression zstd (smaller files), or leave out --log")


def summary(session, ran: int, period_s: float, wall_s: float) -> str:
    """What `hil serve` did, on every exit: periods, the plant's last speed, torque and DC
    link, the board's FAULTs (the first named) and the injected faults."""
    from plant_rt import TRUTH_FIELDS

    from hil.session.bench_session import _fault_text as fault_text

    parts = [f"{ran} periods ({ran * period_s:.3f} s simulated) in {wall_s:.2f} s wall"]
    row = session.recorder.latest_row("truth") if session is not None else None
    if row is not None:
        f = {name: i for i, name in enumerate(TRUTH_FIELDS)}
        parts.append(f"speed {row[f['speed_rpm']]:.1f} rpm, torque {row[f['torque_nm']]:.3f} N m, "
                     f"DC link {row[f['v_dc']]:.1f} V")
    if session is not None:
        faults = session.faults
        parts.append("board FAULTs: none" if not faults else
                     f"board FAULTs: {len(faults)}, the first {fault_text(faults[0], period_s)}")
        parts.append(f"injected fault bits 0x{session.fault_bits:x}" if session.fault_bits
                     else "no injected faults")
    return "hil serve: " + "; ".join(parts)


def _serve(args, profile, config, mailbox, port, live, chunk, total, pace: str) -> int:
    from hil.faults.injector import apply_fault_bits

    with BenchSession(profile, config) as session:
        session.attach_mailbox(mailbox, on_fault_bits=lambda bits: apply_fault_bits(session, bits))
        session.send_command(enable=args.enable, speed_source=args.speed_source,
                             speed_ref_rpm=args.speed_rpm)
        if port is not None:
            port.start()
        where = f", Modbus TCP on {port.host}:{port.port}" if port is not None else ""
        if live is not None:
            session.recorder.live = live
            where += f", live (Foxglove) on {live.url} (open in the app: {live.app_url})"
        print(f"hil serve: board '{session.board_name}' on {args.link}{where}; Ctrl-C stops",
              file=sys.stderr)
        ran = 0
        started = time.monotonic()
        pacer = Pacer(pace, profile.control_period_s)
        status = _StatusLine(session) if sys.stderr.isatty() else None
        log_rate = LogRate(args.log, profile.control_period_s) if args.log is not None else None
        from hil.run.console import EventConsole

        # Notable events as they happen, rate-limited (hil/run/console.py); on a terminal the
        # status line is wiped first so the event stays on a line of its own.
        console = EventConsole(write=(lambda text: print(f"\r\033[K{text}", file=sys.stderr, flush=True))
                               if status is not None else None)
        session.event_listeners.append(console)
        try:
            while total is None or ran < total:
                console.tick()
                if status is not None:
                    status.show(ran)
                n = chunk if total is None else min(chunk, total - ran)
                if live is not None:
                    for error in live.take_errors():
                        print(f"hil serve: live: {error}", file=sys.stderr)
                    pacer.mode = live.pace                  # the viewer may change it
                ran += session.run_periods(n)
                if log_rate is not None:
                    warning = log_rate.warning(ran, time.monotonic() - started, pacer.mode)
                    if warning is not None:
                        print(("\r\033[K" if status is not None else "") + warning,
                              file=sys.stderr, flush=True)
                wait_s = pacer.wait_s(ran, time.monotonic())
                if wait_s > 0:
                    time.sleep(wait_s)
        except KeyboardInterrupt:
            closed = ", log closed" if args.log is not None else ""
            print(f"hil serve: stopping (Ctrl-C): plant safe-stated{closed}", file=sys.stderr)
        finally:
            console.close()
            if port is not None:
                port.stop()
            if status is not None:
                print(file=sys.stderr)             # leave the status line
            # on every exit, a terminal or not, an error or not
            print(summary(session, ran, profile.control_period_s, time.monotonic() - started),
                  file=sys.stderr, flush=True)
            wire = session.tap.wire_stats() if session.tap is not None else {}
            if "wire_projected_rate_hz" in wire:        # lockstep through a modelled wire
                print(f"hil serve: through {wire['wire_model']}: {wire['wire_modelled_s']:.3f} s "
                      f"of modelled wire time, {wire['wire_projected_rate_hz']:.0f} periods/s "
                      f"projected (docs/adapters.md)", file=sys.stderr)
    if args.log is not None:      # closed with the session: its final size
        print(f"hil serve: log {args.log} ({LogRate(args.log, 1.0).size() / 2**20:.1f} MiB)",
              file=sys.stderr, flush=True)
    return 0
