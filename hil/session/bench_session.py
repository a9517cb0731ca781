"""A bench session: a plant, a board on a link, a clock and a log.

The session is the only place where periods happen. Per period, in lockstep:
the plant's sensors are sampled at t_k and sent as SAMPLE k; the board's GATES k
is awaited (one deadline per SAMPLE sent, resent up to answer_resends times: SPEC.md
2.8, hil/session/policy.py); the plant integrates
[t_k, t_k+1] with it (holding the previous gates when none came). Everything
that crossed is recorded in memory (for checks) and in the MCAP log.

Teardown always runs (OpenHTF's lesson): whatever ends a run — its end, a
failed check, a dead board, Ctrl-C — the inverter goes to its safe state
(all switches off, the motor coasts through the diodes), SHUTDOWN is sent, the
board's process is stopped and the log is closed readable.
"""
from __future__ import annotations

import math
import struct
import sys
import time
from dataclasses import field, replace
from pathlib import Path
from typing import Any, Callable

from configfile.dataclass_methods import dataclass
from plant_rt import Plant, TRUTH_FIELDS
from protocol.messages import (
    CAP_DUTY, CAP_DUTY_LEGS, CAP_GATES, LEGS_ALL, PROTOCOL_VERSION, Command, Fault, FaultCode, Gates,
    Duty, DutyLegs, Hello, NonFiniteQuantity, ParamGet, ParamId, ParamSet, ParamValue, Role, Sample,
    Shutdown, SpeedSource, Status, Telemetry,
)

from hil.links.registry import BoardConnection, connect
from hil.logs.recorder import COMMAND_FIELDS, Recorder
from hil.session.adapter_check import check_adapter
from hil.session.board_params import board_parameters, default_board
from hil.session.board_state import BoardState
from hil.control_inputs import ControlInputError, ControlLimits
from hil.session.cpu_latency import CpuLatencyHold
from hil.session.errors import SessionError
from hil.session.link_tap import LinkTap, tappable
from hil.session.policy import CAPABILITY_NAMES, SessionPolicy
from hil.session.realtime import run_realtime
from hil.session.sensor_set import SensorSampler, names_text, read_sensor_set
from hil.session.watchdog import Watchdog, await_answer

RPM_PER_RAD_S = 60.0 / (2.0 * math.pi)
# ccodec.exchange_periods: the answer kind it may take (a board's kind, once known; it hands a
# DUTY_LEGS back to this loop), and the states it ends in that this loop acts on
_ANSWER_CODES = {Gates: 0, Duty: 1}
#: The capability bit (SPEC 9.1) of each answer type.
_ANSWER_CAPS = {Gates: CAP_GATES, Duty: CAP_DUTY, DutyLegs: CAP_DUTY_LEGS}
#: The recorder's step signal of the leg enables in force (DUTY_LEGS answers).
LEG_ENABLE_SIGNAL = "ctrl.leg_enable"
_LOOP_PENDING, _LOOP_STOPPED, _LOOP_LINK_ERROR = 2, 3, 4
_TRUTH_INDEX = {name: i for i, name in enumerate(TRUTH_FIELDS)}
# events that change what drives the plant (the suspects when its state stops being finite)
_INPUT_EVENTS = frozenset({"command", "modbus", "load", "dc_link", "plant_param", "fault",
                           "stimulus", "param"})


class _Lockstep:
    """What one BenchSession._run_lockstep call reads once (the session's parts, the link's
    queue and fast paths, the C loop's arguments), handed to its steps."""
    __slots__ = ("plant", "link", "recorder", "dispatch", "answer_timeout", "sends", "watchdog",
                 "mailbox", "on_period", "publish_every", "tap", "clock", "record_telemetry",
                 "inbox", "fast", "loop", "exchange_periods", "live_every", "direct", "answer")


class _PeriodAnswer:
    """What a period's wait brought: GATES, or the duty (with the leg enables of a DUTY_LEGS);
    the other messages' kinds and whether a TELEMETRY came (a miss's report); when the first
    SAMPLE's deadline began (the watchdog's `since`)."""
    __slots__ = ("gates", "duty", "legs", "others", "saw_telemetry", "first_sent")

    def __init__(self) -> None:
        self.clear()

    def clear(self) -> None:
        """Nothing came yet (one object serves every period of a run: none is made a period)."""
        self.gates = self.duty = self.legs = None
        self.others = None
        self.saw_telemetry = False
        self.first_sent = None


@dataclass
class SessionConfig:
    """How a session is opened: the link, the clock, the log, and overrides of the policy."""

    link: str = "stub"
    mode: str = "lockstep"                  # lockstep | realtime
    log_path: Path | None = None
    # The log's chunk compression (hil.logs.mcap_writer.McapLog): lz4 (its fast mode, the
    # default), zstd (smaller files, more time a period) or none (the least time a period).
    log_compression: str = "lz4"
    seed: int = 0
    # SPEC.md 2.8's session policy: None takes the bench profile's `session` section (its
    # defaults are SPEC's); a value here overrides it (tests, CLI options).
    policy: SessionPolicy | None = None
    watchdog_periods: int | None = None
    watchdog_s: float | None = None
    answer_resends: int | None = None
    hello_tries: int | None = None
    hello_timeout_s: float | None = None    # the HELLO wait per try (policy hello_wait_s)
    answer_timeout_s: float | None = None   # the lockstep answer wait per SAMPLE sent
    realtime_period_s: float | None = None  # None: the profile's control period
    realtime_miss_budget: int = 1000        # deadline misses before a realtime run ends in ERROR
    # Frames pass through a LinkTap (raw-frame log, link-fault injection) where the link
    # carries bytes; CAN links carry frames and are not tapped.
    tap_link: bool = True
    # Hold /dev/cpu_dma_latency at 0 while the session is open (hil/session/cpu_latency.py) when the
    # board is another process or device (over a pty it answers about 4x sooner) and in real
    # time (wake-ups on time). The in-process stub in lockstep never waits: no hold.
    hold_cpu_latency: bool = True
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)
    # The board file (hil.boards.BoardFile): which parameters the board takes and what is
    # pushed to it. None: the stub's for the stub's links, else a board from SPEC.md alone.
    board: Any = None
    # The profile's name or file, for the board file's profile_settings.
    profile_label: str | None = None


@dataclass
class CommandState:
    """What the bench has asked the board to do, in engineering units."""

    enable: bool = False
    speed_source: str = "encoder"   # encoder | conventional | ekf
    speed_ref_rpm: float = 0.0
    torque_mode: bool = False
    torque_ref_nm: float = 0.0
    flux_ref_wb: float = 0.0        # 0: the board's PARAM flux_ref_wb

    def to_message(self, default_flux_wb: float) -> Command:
        flags = (1 if self.enable else 0) | (2 if self.torque_mode else 0)
        source = {"encoder": SpeedSource.ENCODER, "conventional": SpeedSource.CONVENTIONAL,
                  "ekf": SpeedSource.EKF}[self.speed_source]
        return Command(flags=flags, speed_source=int(source),
                       speed_ref_rad_s=self.speed_ref_rpm / RPM_PER_RAD_S,
                       torque_ref_nm=self.torque_ref_nm,
                       flux_ref_wb=self.flux_ref_wb or default_flux_wb)

    def row(self) -> tuple:
        source = ("encoder", "conventional", "ekf").index(self.speed_source)
        return (float(self.enable), float(source), self.speed_ref_rpm, float(self.torque_mode),
                self.torque_ref_nm, self.flux_ref_wb)


class BenchSession:
    """Plant + board + clock + log. Use as a context manager; ``close`` always runs."""

    def __init__(self, profile, config: SessionConfig | None = None,
                 on_period: Callable[[int], None] | None = None):
        self.profile = profile
        self.config = config or SessionConfig()
        self.plant = Plant(profile, seed=self.config.seed)
        self.period_s = profile.control_period_s
        self.command_state = CommandState()
        self.recorder = Recorder(self.period_s)
        self.conn: BoardConnection | None = None
        self.log = None
        self.board_hello: Hello | None = None
        self.board_params: dict[str, float] = {}
        self.board = self.config.board if self.config.board is not None else \
            default_board(self.config.link)
        # the board file's profile_settings key: the given label, else the profile file's stem
        self.profile_label = self.config.profile_label or str(profile.source)
        self.faults: list[Fault] = []
        self.board_state = BoardState(self.period_s, self.recorder)   # from STATUS: ready or not
        self.events: list[tuple[float, str, dict]] = []
        #: Called as fn(t_s, kind, data) for every event as it is recorded (the console, a
        #: live view). A listener must be quick: it runs inside the period loop.
        self.event_listeners: list = []
        self.missed_answers = 0
        self.policy = _policy(profile, self.config)
        self.hello_wait_s = self.policy.hello_wait_s
        self.answer_wait_s = self.policy.answer_wait_s(self.period_s)
        self.watchdog = Watchdog(self.policy.watchdog_periods,
                                 self.policy.effective_watchdog_s(self.period_s))
        self.stale_answers = 0
        self.resent_samples = 0
        self.board_faults = 0
        self.shoot_throughs = 0
        self._answer_kind: type | None = None    # GATES, DUTY or DUTY_LEGS, the first the board answered
        self._leg_enable_logged = -1             # the last DUTY_LEGS leg enables recorded
        self._streak_others: set[str] = set()    # non-answer types received while periods miss
        self._streak_stale = 0
        self._last_stale: tuple[str, int] | None = None
        self._drained_period = -1
        self.error: str | None = None
        self.on_period = on_period
        self._gates = 0
        self._closed = False
        self._mailbox = None
        self._on_fault_bits: Callable[[int], None] | None = None
        self.rt_answered_period: int | None = None   # real time: newest period answered
        # Modbus input registers are refreshed every 10 ms of simulated time.
        self.publish_every = max(1, round(0.01 / self.period_s))
        self.fault_bits = 0
        self.fault_injector = None      # hil.faults.injector(session) creates it on first use
        self.tap: LinkTap | None = None
        self.rt_stats: dict[str, Any] = {}
        self.cpu_latency = CpuLatencyHold()
        # SPEC 6.13: the board's sensor set (None: no SENSOR_SET capability, today's SAMPLE)
        # and what makes its SAMPLE_SENSORS every period
        self.sensor_set: int | None = None
        self.sensor_sampler: SensorSampler | None = None

    # ----------------------------------------------------------------- setup
    def __enter__(self) -> "BenchSession":
        try:
            self.start()
        except BaseException:
            self.close()
            raise
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        self.close(reason=None if exc is None else f"{exc_type.__name__}: {exc}")

    def start(self) -> None:
        cfg = self.config
        if cfg.hold_cpu_latency and (cfg.link != "stub" or cfg.mode == "realtime"):
            self.cpu_latency.acquire()
        if cfg.log_path is not None:
            from hil.logs.mcap_writer import McapLog

            self.log = McapLog(cfg.log_path, metadata=self._metadata(),
                               compression=cfg.log_compression)
            self.recorder.attach_log(self.log)
        self.conn = connect(cfg.link)
        if cfg.tap_link and tappable(self.conn.link):
            self.tap = self.conn.link = LinkTap(self.conn.link, seed=cfg.seed, wire=self.conn.wire,
                                                delay_frames=cfg.mode == "realtime")
        elif self.conn.wire is not None:
            raise SessionError(f"{self._where()}: wire={self.conn.wire.name} needs a byte link "
                               "with the link tap (serial framing), not CAN frames")
        self.adapter = check_adapter(cfg.link, self.conn, self.log)   # docs/adapters.md
        self._apply_link_waits()
        try:
            self._handshake()
            self._start_sensor_set()
            self._push_parameters(board_parameters(self.profile, self.board,
                                                   self.profile_label))
        except SessionError as exc:
            self.plant.safe_state()
            self.error = str(exc)
            self._event("refused", {"reason": str(exc)})
            raise
        except OSError as exc:              # LinkError: the line failed during the handshake
            self.plant.safe_state()
            if self.conn.process is not None and self.conn.board_alive():
                try:    # a process that closed its line is usually exiting: let its status arrive
                    self.conn.process.wait(0.5)
                except Exception:  # noqa: BLE001
                    pass
            self.error = self._with_report(f"{self._where()}: link failed before the first "
                                           f"SAMPLE: {exc}")
            self._event("link_failed", {"reason": self.error})
            raise SessionError(self.error) from exc
        self.send_command()

    def _apply_link_waits(self) -> None:
        """SPEC 2.8: a link that starts the board itself may raise the waits (QEMU); the
        in-process library answers within the call (wait 0). SessionConfig overrides both."""
        cfg, conn, policy = self.config, self.conn, self.policy
        hello = policy.hello_wait_s
        if conn.hello_wait_s is not None:
            hello = 0.0 if conn.hello_wait_s == 0.0 else max(hello, conn.hello_wait_s)
        min_s = policy.answer_wait_min_s
        if conn.answer_wait_min_s is not None:
            min_s = 0.0 if conn.answer_wait_min_s == 0.0 else max(min_s, conn.answer_wait_min_s)
        answer = max(policy.answer_wait_periods * self.period_s, min_s)
        if conn.answer_wait_min_s == 0.0:
            answer = 0.0
        self.hello_wait_s = hello if cfg.hello_timeout_s is None else cfg.hello_timeout_s
        self.answer_wait_s = answer if cfg.answer_timeout_s is None else cfg.answer_timeout_s
        watchdog_s = max(policy.watchdog_s, (1 + policy.answer_resends) * self.answer_wait_s)
        self.watchdog = Watchdog(policy.watchdog_periods, watchdog_s)

    def _where(self) -> str:
        return f"board on '{self.config.link}'"

    def _with_report(self, text: str) -> str:
        """Appends how the board process ended (exit status, last stderr lines), if it did."""
        report = self.conn.report() if self.conn is not None else ""
        return f"{text}; {report}" if report else text

    def _rx_decoder(self):
        """The stream decoder that sees what the board sends (the tap's, or the link's)."""
        link = self.conn.link
        return getattr(link, "_decoder", None) or getattr(link, "decoder", None)

    def _metadata(self) -> dict[str, dict[str, str]]:
        import platform
        import hil

        meta = {
            "bench": {"hil_bench_version": hil.__version__, "python": platform.python_version(),
                      "machine": platform.machine(), "link": self.config.link,
                      "mode": self.config.mode, "seed": str(self.config.seed),
                      "cpu_dma_latency": self.cpu_latency.status,
                      "protocol_version": str(PROTOCOL_VERSION)},
            "profile": {k: str(v) for k, v in _flatten(self.profile.as_dict()).items()},
            "board": {"name": self.board.name, "source": self.board.source,
                      **{f"settings.{s.name}": repr(s.value)
                         for s in board_parameters(self.profile, self.board,
                                                   self.profile_label)}},
        }
        meta.update(self.config.metadata)
        return meta

    def _await(self, predicate: Callable[[Any], bool], timeout_s: float, what: str,
               check: Callable[[], None] | None = None):
        """Receives until a message satisfies predicate within one deadline; other messages
        are dispatched and do not extend it. None when the deadline passed."""
        return await_answer(self.conn.link, predicate, timeout_s, self.dispatch, check=check,
                            slice_s=0.05 if check is not None else None)

    def _check_version(self) -> None:
        dec = self._rx_decoder()
        if dec is not None and dec.version_errors:
            raise SessionError(self._with_report(
                f"{self._where()} sends frames of protocol version {dec.last_bad_version}, "
                f"the bench speaks version {PROTOCOL_VERSION}"))

    def _handshake(self) -> None:
        """SPEC 2.8 and 2.8.4: HELLO up to hello_tries times, then the refusals."""
        link, policy = self.conn.link, self.policy
        period_ns = round(self.period_s * 1e9)
        mine = Hello(proto_version=PROTOCOL_VERSION, role=int(Role.BENCH), capabilities=0,
                     control_period_ns=period_ns, name_len=len(b"hil-bench"), name=b"hil-bench")
        self._seen_during_hello: dict[str, int] = {}
        hello = None
        tries = policy.hello_tries if self.config.hello_tries is None else self.config.hello_tries
        for _ in range(tries):
            link.send(mine)
            hello = self._await(lambda m: isinstance(m, Hello), self.hello_wait_s, "HELLO",
                                check=self._check_version)
            if hello is not None:
                break
            if not self.conn.board_alive():
                break
        if hello is None:
            raise SessionError(self._with_report(
                f"no HELLO from the {self._where()} after {tries} tries of "
                f"{self.hello_wait_s:g} s: {self._hello_silence()}"))
        where = self._where()
        if hello.proto_version != PROTOCOL_VERSION:
            raise SessionError(f"{where} speaks protocol version {hello.proto_version}, "
                               f"the bench speaks version {PROTOCOL_VERSION}")
        if hello.role != int(Role.CONTROLLER):
            role = {0: " (bench)"}.get(hello.role, "")
            raise SessionError(f"{where} says role {hello.role}{role} in its HELLO; "
                               f"a controller is role {int(Role.CONTROLLER)}")
        caps = hello.capabilities
        if not caps & (CAP_GATES | CAP_DUTY | CAP_DUTY_LEGS):
            raise SessionError(f"{where} advertises none of GATES, DUTY and DUTY_LEGS "
                               f"(capabilities 0x{caps:04x})")
        for name in policy.require_capabilities:
            if not caps & (1 << CAPABILITY_NAMES.index(name)):
                raise SessionError(f"{where} lacks capability {name}, required by the profile "
                                   f"(session.require_capabilities)")
        for name in self.board.capabilities:
            if not caps & (1 << CAPABILITY_NAMES.index(name)):
                raise SessionError(f"{where} lacks capability {name}, which its board file "
                                   f"{self.board.source} says it has (capabilities 0x{caps:04x})")
        if hello.control_period_ns not in (0, period_ns):
            raise SessionError(f"{where} was built for a control period of "
                               f"{hello.control_period_ns} ns, the bench runs {period_ns} ns")
        self.board_hello = hello
        self._event("hello", {"board": _name(hello), "proto_version": hello.proto_version,
                              "capabilities": caps, "control_period_ns": hello.control_period_ns})

    def _start_sensor_set(self) -> None:
        """SPEC 6.13: a board with the SENSOR_SET capability says its set (checked against its
        board file); it gets SAMPLE_SENSORS from the plant's sensor frame from now on. Its
        periods, and a SAMPLE board's on a profile whose thermal model is on (the winding
        temperature logged from Python), run in the Python period loop."""
        self.sensor_set = read_sensor_set(self)
        if self.sensor_set is None:
            if self.profile.thermal.enabled:    # the winding temperature, logged per period
                self.sensor_sampler = SensorSampler(self.plant, None, self.recorder)
            return
        self.sensor_sampler = SensorSampler(self.plant, self.sensor_set, self.recorder)
        self._event("sensor_set", {"sensor_set": self.sensor_set,
                                   "sensors": names_text(self.sensor_set)})

    def _hello_silence(self) -> str:
        """What arrived instead of a HELLO: every non-zero error counter (SPEC 2.9)."""
        counters = self.conn.link.counters
        words = {"crc_errors": "frames failed their CRC", "framing_errors": "framing errors",
                 "seq_gaps": "sequence gaps", "unknown_types": "frames of unknown types",
                 "length_errors": "length errors", "sequence_errors": "CAN sequence errors",
                 "ignored_frames": "ignored CAN frames", "own_role_frames": "frames with the bench's own role"}
        parts = [f"{counters[k]} {w}" for k, w in words.items() if counters.get(k)]
        seen = [f"{n} {t}" for t, n in self._seen_during_hello.items()]
        if seen:
            parts.append("received only " + ", ".join(seen))
        if not parts:
            return "nothing received"
        text = ", ".join(parts)
        if counters.get("crc_errors") or counters.get("framing_errors"):
            text += " (wrong baud rate or a noisy line?)"
        return text

    def _push_parameters(self, settings) -> None:
        """SPEC 2.8.3 for each setting; an optional one the board does not know is logged
        and skipped, anything else refused ends the session naming the parameter."""
        caps = self.board_hello.capabilities if self.board_hello is not None else 0xFFFF
        for setting in settings:
            if setting.name == "telemetry_divider" and not caps & 0x4:
                self._event("param_skipped", {"name": setting.name, "reason": "the board does "
                                              "not advertise the TELEMETRY capability"})
                continue
            self.param_set(setting.name, setting.value, optional=setting.optional)

    def _param_exchange(self, msg, pid: int, what: str) -> ParamValue:
        """Sends msg and waits param_wait_s for the PARAM_VALUE of pid, param_tries times."""
        policy = self.policy
        wait = policy.param_wait_s if self.hello_wait_s > 0.0 else 0.0
        for _ in range(policy.param_tries):
            self.conn.link.send(msg)
            answer = self._await(lambda m: isinstance(m, ParamValue) and m.id == pid, wait, what)
            if answer is not None:
                return answer
            if not self.conn.board_alive():
                break
        raise SessionError(self._with_report(
            f"{self._where()}: no PARAM_VALUE for {what} after {policy.param_tries} tries of "
            f"{wait:g} s"))

    def param_set(self, name: str, value: float, optional: bool = False) -> float:
        """PARAM_SET then PARAM_GET (SPEC 2.8.3): returns the value in force (float32). The
        name and value are checked against the board file first. `optional`: an UNKNOWN answer
        is logged and NaN returned instead of ending the session."""
        problem = self.board.check_value(name, float(value))
        if problem is not None:
            raise SessionError(f"{self._where()}: {problem}")
        pid = self.board.param(name).id
        where = self._where()
        answer = self._param_exchange(ParamSet(id=int(pid), value=float(value)), int(pid),
                                      f"parameter {name} (PARAM_SET)")
        status = answer.status
        if status == 1 and optional:
            text = f"{where} does not know optional parameter {name} (id {int(pid)}): not set"
            self._warn(text)
            self._event("param_unknown", {"name": name, "id": int(pid), "requested": float(value)})
            return math.nan
        if status == 1:
            raise SessionError(f"{where} does not know parameter {name} (id {int(pid)}, "
                               f"status 1 UNKNOWN; board file {self.board.source})")
        if status != 0:
            raise SessionError(f"{where} refused parameter {name} = {value:g} (status {status} "
                               f"{_param_status(status)}; keeps {answer.value:g})")
        requested = _f32(value)
        clamped = _f32(answer.value) != requested
        if clamped and pid == int(ParamId.CONTROL_PERIOD_S):
            raise SessionError(f"{where} was built for a control period of "
                               f"{_ns_text(answer.value)}, the bench runs "
                               f"{round(self.period_s * 1e9)} ns (CONTROL_PERIOD_S {value:g} "
                               f"answered {answer.value:g})")
        if not math.isfinite(answer.value):
            # a board's answer is an input like any other: a non-finite value in force is
            # refused, not logged as a clamp (SPEC 2.8.3)
            raise SessionError(f"{where} answered parameter {name} = {value:g} with a "
                               f"non-finite value in force ({answer.value!r})")
        readback = self._param_exchange(ParamGet(id=int(pid)), int(pid),
                                        f"parameter {name} (PARAM_GET)")
        if readback.status != 0 or _f32(readback.value) != _f32(answer.value):
            raise SessionError(f"{where}: parameter {name}: PARAM_SET answered {answer.value:g}, "
                               f"PARAM_GET reads back {readback.value:g} (status {readback.status})")
        self.board_params[name] = readback.value
        if clamped:
            text = (f"parameter {name}: requested {value:g}, the board clamped it to "
                    f"{answer.value:g} (in force)")
            self._warn(text)
            self._event("param_clamped", {"name": name, "requested": float(value),
                                          "value": readback.value})
        else:
            self._event("param", {"name": name, "value": readback.value})
        return readback.value

    # -------------------------------------------------------------- commands
    def send_command(self, **changes: Any) -> None:
        """Updates the command state (engineering units) and sends COMMAND."""
        unknown = set(changes) - set(COMMAND_FIELDS)
        if unknown:
            raise ValueError(f"unknown command field(s): {', '.join(sorted(unknown))}")
        changes = self.control_limits.command(changes)   # ControlInputError names a bad one
        if "enable" in changes and bool(changes["enable"]) != self.command_state.enable:
            self.board_state.enable_changed(self.plant.period)  # not ready until it says so
        self.command_state = replace(self.command_state, **changes)
        msg = self.command_state.to_message(self.board_params.get("flux_ref_wb", 0.0))
        self.conn.link.send(msg)
        self.recorder.command(self.plant.period, self.command_state.row())
        self._event("command", dict(changes))

    _control_limits: ControlLimits | None = None
    inputs_refused = 0          # control inputs refused on their way in (counted per session)

    @property
    def control_limits(self) -> ControlLimits:
        """The ranges of every control input (hil/control_inputs.py), from the profile."""
        if self._control_limits is None:
            self._control_limits = ControlLimits.from_profile(self.profile)
        return self._control_limits

    def _refuse_input(self, source: str, exc: ControlInputError) -> None:
        """A control input refused on its way in: counted, named in an event; the run goes on."""
        self.inputs_refused += 1
        self._event("input_refused", {"source": source, "input": exc.name, "value": repr(exc.value),
                                      "reason": exc.why})

    @property
    def board_name(self) -> str:
        return _name(self.board_hello) if self.board_hello is not None else ""

    def _event(self, kind: str, data: dict) -> None:
        t = self.plant.period * self.period_s
        self.events.append((t, kind, data))
        for listener in self.event_listeners:
            listener(t, kind, data)
        if self.log is not None:
            self.log.write_json("/plan/events", round(t * 1e9), {"t_s": t, "kind": kind, **_jsonable(data)})

    def _warn(self, text: str) -> None:
        """A warning on stderr, naming the plan and profile of the run when it has them."""
        plan = self.config.metadata.get("plan") or {}
        whose = f"{plan['name']} [{plan.get('profile', '')}]: " if plan.get("name") else ""
        print(f"hil: warning: {whose}{text}", file=sys.stderr)

    def event(self, kind: str, **data: Any) -> None:
        """Records a plan event (stimulus, mark, fault) in the event list and the log."""
        self._event(kind, data)

    # ----------------------------------------------------------- dispatching
    def dispatch(self, msg) -> None:
        """Handles a message that is not the awaited answer (telemetry, faults, status)."""
        t = type(msg)
        if t is Telemetry:
            self.recorder.telemetry(msg)
        elif t is Fault:
            self.faults.append(msg)
            self.recorder.step_value("ctrl.fault_code", msg.period, msg.code)
            self._event("board_fault", {"code": msg.code, "period": msg.period, "value": msg.value})
            self.board_faults += 1
            if self.board_faults == 1:
                self._warn(_fault_text(msg, self.period_s))
        elif t is Status:
            self.recorder.step_value("ctrl.fault_code", msg.period, msg.fault_code)
            self.board_state.on_status(msg.state, msg.fault_code, msg.period, self.plant.period)
            self._event("board_status", {"state": msg.state, "fault_code": msg.fault_code,
                                         "period": msg.period})
        elif t is Gates or t is Duty or t is DutyLegs:
            self.stale_answers += 1
            self._last_stale = (t.TYPE.name, msg.period)
        if self.board_hello is None and self.conn is not None:
            seen = self._seen_during_hello
            name = t.__name__.upper()
            seen[name] = seen.get(name, 0) + 1
        # HEARTBEAT, late PARAM_VALUEs: nothing to do beyond the raw-frame log

    # --------------------------------------------------------------- running
    def run_periods(self, count: int, stop: Callable[[], bool] | None = None) -> int:
        """Advances up to ``count`` periods (lockstep or real time); returns how many ran."""
        first = self.plant.period
        try:
            if self.config.mode == "realtime":
                ran = run_realtime(self, count, stop)
            else:
                ran = self._run_lockstep(count, stop)
        except (ValueError, OverflowError) as exc:   # int(NaN) in the sensors, math on inf
            self._check_plant_finite(first, exc)
            raise
        self._check_plant_finite(first)
        return ran

    def _check_plant_finite(self, first: int, exc: Exception | None = None) -> None:
        """Once per run_periods call (the period loop is not slowed): a plant state that is
        no longer finite ends the run in ERROR, naming the quantity and the last input."""
        bad = self.plant.non_finite_state()
        if bad is None:
            return
        self.plant.safe_state()
        k = self.plant.period
        cause = next(((t, kind, data) for t, kind, data in reversed(self.events)
                      if kind in _INPUT_EVENTS), None)
        last = (f"; the last input before it: {cause[1]} {_jsonable(cause[2])} at t = "
                f"{cause[0]:.6g} s" if cause is not None else "; no input was changed")
        self.error = (f"the plant's state is no longer finite at period {k} (t = {k * self.period_s:.6g} s; "
                      f"finite at period {first}): {bad[0]} = {bad[1]!r}{last}")
        self._event("plant_not_finite", {"period": k, "quantity": bad[0], "reason": self.error})
        raise SessionError(self.error) from exc

    def _run_lockstep(self, count: int, stop: Callable[[], bool] | None) -> int:
        """SPEC 2.8.1: one deadline per SAMPLE sent; SAMPLE(k) is resent (same values) up to
        answer_resends times before period k counts as missed and the plant holds its gates."""
        run = self._lockstep_setup()
        done = 0
        while done < count:
            pending = False          # period k sampled, recorded and sent by the C loop
            sent_at = None           # when it went, over a descriptor (its answer wait runs)
            if run.loop is not None and not run.watchdog.consecutive and \
                    (run.tap.direct_ready if run.direct else run.tap.fast_ready):
                ran, state, extra = self._run_c_periods(run, count - done, stop)
                done += ran
                if state == _LOOP_STOPPED:
                    return done
                if done >= count:
                    return count
                pending = state == _LOOP_PENDING
                sent_at = extra
            self._lockstep_period(run, pending, sent_at)
            done += 1
            if stop is not None and stop():
                return done
        return count

    def _lockstep_setup(self) -> _Lockstep:
        """What a _run_lockstep call reads once: the session's parts, the link's queue and
        fast paths, and the C period loop's arguments when it may run."""
        run = _Lockstep()
        run.answer = _PeriodAnswer()
        run.plant = self.plant
        run.link = self.conn.link
        run.recorder = recorder = self.recorder
        run.dispatch = self.dispatch
        run.answer_timeout = answer_timeout = self.answer_wait_s
        run.sends = 1 + self.policy.answer_resends
        run.watchdog = self.watchdog
        run.mailbox = mailbox = self._mailbox
        run.on_period = on_period = self.on_period
        run.publish_every = self.publish_every
        run.tap = tap = self.tap
        run.clock = time.monotonic
        run.record_telemetry = recorder.telemetry
        # what the link tap has already decoded is taken without a call (its recv() would
        # pop the same queue first); an untapped link has no such queue
        run.inbox = tap.inbox if tap is not None else ()
        # What dispatch() does with a TELEMETRY, less the hop; a board still in HELLO takes
        # dispatch()'s path (it notes what the board sent before its HELLO).
        if self.board_hello is None:
            run.record_telemetry = run.dispatch
        # A firmware library in this process with the C codec: SAMPLE out and the answers in
        # through one C call while no link fault is active (hil/session/link_tap.py).
        # A sensor-set board's SAMPLE_SENSORS is made from the plant's Python sensor frame, and
        # the winding temperature is logged from Python: this loop sends and records them (the
        # C exchange and period loop know only SAMPLE and its rows).
        python_only = self.sensor_sampler is not None
        run.fast = fast = tap.sample_exchanger() if tap is not None and not python_only else None
        # The plain periods in between, each one the C loop (ccodec.exchange_periods: the same
        # steps, the same order, no Python frame) while nothing needs this loop: no mailbox or
        # per-period stimulus, the answer kind known and no miss being counted; it hands back
        # every period it does not take (see its docstring), and a live viewer's rows.
        run.loop = None
        run.exchange_periods = None
        run.live_every = 0
        run.direct = direct = fast is None   # the descriptor kind (LinkTap.descriptor_target)
        if (tap is not None and mailbox is None and not python_only
                and self.board_hello is not None
                and (on_period is None or getattr(on_period, "idle", False))):
            target = tap.descriptor_target(answer_timeout) if direct else fast.args
            if target is not None:     # (the tap made it with the C codec: already imported)
                from protocol.ccodec import exchange_periods
                if exchange_periods is not None:
                    live = recorder.live        # its rows (every live.every-th) stay here
                    run.exchange_periods = exchange_periods
                    run.loop = (target, run.plant.sample, run.plant.truth, run.plant.step,
                                recorder.batch_stage(), recorder.seal, run.publish_every)
                    run.live_every = live.every if live is not None else 0
        return run

    def _run_c_periods(self, run: _Lockstep, count: int, stop: Callable[[], bool] | None):
        """Up to `count` plain periods in the C loop: (periods done, its end state, its extra:
        when the pending SAMPLE went, or the link's error, which fails the session here)."""
        answer = _ANSWER_CODES.get(self._answer_kind, -1)
        ran, state, extra = run.exchange_periods(*run.loop, count, stop, answer, run.live_every)
        if run.direct:
            run.tap.settle_direct()
        if state == _LOOP_LINK_ERROR:  # period k recorded, the plant not stepped
            self._link_failed(run.plant.period, run.tap.direct_failure(*extra))
        return ran, state, extra

    def _lockstep_period(self, run: _Lockstep, pending: bool, sent_at: float | None) -> None:
        """One period in this loop: the mailbox's inputs, the sample, its exchange with the
        board (the SAMPLE already sent by the C loop when `pending`), the plant's step on the
        answer or on a miss, the per-period hook and the mailbox's publication."""
        mailbox = run.mailbox
        if mailbox is not None and mailbox.pending:
            self._apply_mailbox(mailbox)
        sampler = self.sensor_sampler
        if sampler is None:
            sample, msg_out = run.plant.sample(), None
        else:
            sample, msg_out = sampler()
        k = sample.period
        tap = run.tap
        if tap is not None:
            tap.tick(k)
            if k % run.publish_every == 0:
                run.recorder.frames(k, tap.take_capture())
        answer = self._exchange_period(run, k, sample, pending, sent_at, msg_out)
        if answer.gates is None and answer.duty is None:
            self._answer_missed(run, k, answer)
        else:
            self._answer_taken(run, k, answer)
        if run.on_period is not None:
            run.on_period(k)
        if mailbox is not None and k % run.publish_every == 0:
            self._publish(mailbox, k)

    def _exchange_period(self, run: _Lockstep, k: int, sample, pending: bool,
                         sent_at: float | None, msg_out=None) -> _PeriodAnswer:
        """SAMPLE(k) (or a sensor-set board's SAMPLE_SENSORS(k), `msg_out`) out, up to
        run.sends times, each with its own deadline, the same message each time; the period's
        record made while the board computes; what came back. A link failure fails the
        session (the period recorded first)."""
        answer = run.answer
        answer.clear()
        fast = run.fast
        tap = run.tap
        answer_timeout = run.answer_timeout
        recorded = pending
        recording = False
        try:
            for attempt in range(run.sends):
                if attempt:
                    self.resent_samples += 1
                if pending and not attempt:
                    pass                      # sent by the C loop
                elif fast is not None and not attempt and tap.fast_ready:
                    fast(k, sample.adc_i1, sample.adc_i2, sample.adc_vdc, sample.encoder,
                         sample.status)
                else:
                    if msg_out is None:
                        msg_out = Sample(k, sample.adc_i1, sample.adc_i2, sample.adc_vdc,
                                         sample.encoder, sample.status)
                    run.link.send(msg_out)
                # One deadline per SAMPLE: other traffic is handled but never extends it.
                # It runs from the send, or, when messages were already queued behind it
                # (a firmware in this process answers inside the call), from the first
                # moment nothing is queued and the bench would wait: the queue is what was
                # already received, so no clock is read while the answer is in it.
                if sent_at is not None and not attempt:
                    deadline = sent_at + answer_timeout
                else:
                    deadline = None if run.inbox else run.clock() + answer_timeout
                if answer.first_sent is None and deadline is not None:
                    answer.first_sent = deadline - answer_timeout
                if not recorded:
                    # The period's record needs nothing from the answer: made while a
                    # board in another process or on a wire computes it (off the critical
                    # path of stub-pty and real boards), inside the same deadline. A
                    # failing log (a full disk) is not the link's failure: `recording`
                    # lets it through the handler below as it is.
                    recorded = recording = True
                    run.recorder.period(k, run.plant.truth(), sample)
                    recording = False
                self._take_messages(run, k, deadline, answer)
                if answer.gates is not None or answer.duty is not None:
                    break
        except (OSError, ValueError) as exc:  # LinkError is an OSError: the line is gone
            if recording:
                raise
            if not recorded:
                run.recorder.period(k, run.plant.truth(), sample)
            self._link_failed(k, exc)
        return answer

    def _take_messages(self, run: _Lockstep, k: int, deadline: float | None,
                       answer: _PeriodAnswer) -> None:
        """The board's messages until period k's answer or the deadline (None: it starts when
        the queue runs empty): the answer into `answer`, stale answers counted, TELEMETRY to
        the recorder, the rest dispatched and named."""
        inbox = run.inbox
        link = run.link
        clock = run.clock
        answer_timeout = run.answer_timeout
        late = False                  # past the deadline: take only what is queued
        while True:
            if inbox:
                msg = inbox.popleft()
            else:
                now = clock()
                if deadline is None:
                    deadline = now + answer_timeout
                    if answer.first_sent is None:
                        answer.first_sent = now
                if late:
                    msg = link.recv(0.0)
                    if msg is not None and answer_timeout > 0.0 and \
                            now > deadline + answer_timeout:
                        return        # a flood: this wait is lost
                else:
                    wait = deadline - now
                    if wait <= 0.0:
                        late = True
                        msg = link.recv(0.0)
                    else:
                        msg = link.recv(wait)
                if msg is None:
                    return
            t = type(msg)
            if t is Gates:
                if msg.period == k:
                    answer.gates = msg.gates & 0x3F    # bits 6-7 reserved: ignored (SPEC 4)
                    return
                self.stale_answers += 1
                self._last_stale = ("GATES", msg.period)
            elif t is Duty or t is DutyLegs:
                if msg.period == k:
                    d = msg.duty
                    answer.duty = (d[0] / 65535.0, d[1] / 65535.0, d[2] / 65535.0)
                    if t is DutyLegs:
                        answer.legs = msg.leg_enable & LEGS_ALL  # reserved bits ignored (SPEC 4)
                    return
                self.stale_answers += 1
                self._last_stale = ("DUTY" if t is Duty else "DUTY_LEGS", msg.period)
            elif t is Telemetry:
                # every period's companion: straight to the recorder; named among
                # "others" only if the period goes unanswered
                run.record_telemetry(msg)
                answer.saw_telemetry = True
            else:
                run.dispatch(msg)
                if answer.others is None:
                    answer.others = set()
                answer.others.add(t.__name__.upper())

    def _answer_missed(self, run: _Lockstep, k: int, answer: _PeriodAnswer) -> None:
        """Period k went unanswered: counted, the streak's other traffic noted for the
        watchdog's report, the watchdog told (it may trip), the plant's gates held."""
        self.missed_answers += 1
        others = answer.others
        if answer.saw_telemetry:
            others = (others or set()) | {"TELEMETRY"}
        if others:
            self._streak_others |= others
        watchdog = run.watchdog
        if watchdog.consecutive == 0:
            self._streak_first = k
            self._streak_stale = self.stale_answers
        why = watchdog.missed(since=answer.first_sent)
        self._event("missed", {"period": k, "samples_sent": run.sends})
        if why is not None:
            self._watchdog_tripped(k, run.sends)
        run.plant.step(None)

    def _answer_taken(self, run: _Lockstep, k: int, answer: _PeriodAnswer) -> None:
        """Period k's answer drives the plant (a shoot-through GATES word reported first)."""
        watchdog = run.watchdog
        if watchdog.consecutive:          # (answered() at 0 would change nothing)
            self._streak_others.clear()
            watchdog.answered()
        gates, duty = answer.gates, answer.duty
        if duty is None:
            if gates & (gates >> 1) & 0x15:
                self._shoot_through(k, gates)
            run.plant.step(gates)
            if self._answer_kind is not Gates:
                self._note_answer_kind(Gates)
        elif answer.legs is None:
            run.plant.step(duty=duty)
            if self._answer_kind is not Duty:
                self._note_answer_kind(Duty)
        else:
            self._step_duty_legs(duty, answer.legs)

    def _step_duty_legs(self, duty: tuple[float, float, float], legs: int) -> None:
        """A DUTY_LEGS answer: the plant floats the legs whose bit is 0; the leg enables in
        force are recorded as a step signal when they change."""
        k = self.plant.period
        self.plant.step(duty=duty, legs=legs)
        if legs != self._leg_enable_logged:
            self._leg_enable_logged = legs
            self.recorder.step_value(LEG_ENABLE_SIGNAL, k, legs)
        if self._answer_kind is not DutyLegs:
            self._note_answer_kind(DutyLegs)

    def _note_answer_kind(self, kind: type) -> None:
        """SPEC 2.8.4: a board answering with a type it does not advertise is accepted, logged once."""
        first = self._answer_kind is None
        self._answer_kind = kind
        caps = self.board_hello.capabilities if self.board_hello is not None else 0x3
        bit = _ANSWER_CAPS[kind]
        if first and not caps & bit:
            self._event("answer_type", {"type": kind.TYPE.name, "capabilities": caps,
                                        "note": "answers with a type it does not advertise"})
        elif not first:
            self._event("answer_type", {"type": kind.TYPE.name,
                                        "note": "the board switched answer type"})

    def _shoot_through(self, k: int, gates: int) -> None:
        self.shoot_throughs += 1
        if self.shoot_throughs > 1:
            return
        legs = [leg for leg, bit in (("A", 0x01), ("B", 0x04), ("C", 0x10))
                if gates & bit and gates & (bit << 1)]
        turns = ", ".join(f"{leg} high and {leg} low" for leg in legs)
        text = (f"period {k} (t = {k * self.period_s:.6g} s): GATES 0x{gates:02x} turns on {turns} "
                f"together (shoot-through); the plant's driver trip opened leg {', '.join(legs)}")
        self._warn(text)
        self._event("shoot_through", {"period": k, "gates": gates, "legs": legs})

    def _watchdog_tripped(self, k: int, sends: int) -> None:
        """SPEC 2.9's watchdog messages: silent, only other traffic, or stale answers."""
        self.plant.safe_state()
        wd = self.watchdog
        first = getattr(self, "_streak_first", k)
        stale = self.stale_answers - self._streak_stale
        if stale:
            last = self._last_stale
            why = (f"no GATES/DUTY for period {first} in {wd.elapsed_s:.1f} s; the board answered "
                   f"{stale} times with other periods (last: {last[0]} for period {last[1]}): "
                   f"stale answers")
        else:
            span = f"period {first}" if first == k else f"periods {first}..{k}"
            why = (f"no GATES/DUTY for {wd.consecutive} consecutive periods ({span}, {sends} "
                   f"SAMPLEs each, {wd.elapsed_s:.1f} s), ")
            others = sorted(self._streak_others)
            why += f"board sent only {', '.join(others)}" if others else "board silent"
        why = self._with_report(why)
        self.error = (f"watchdog: {why}; at period {k} (t = {k * self.period_s:.6f} s) on "
                      f"'{self.config.link}'")
        self._event("watchdog", {"period": k, "reason": why})
        raise SessionError(self.error)

    @property
    def consecutive_misses(self) -> int:
        return self.watchdog.consecutive

    def _link_failed(self, k: int, exc: Exception) -> None:
        self.plant.safe_state()
        if self.conn.process is not None and self.conn.board_alive():
            try:    # a process that closed its line is usually exiting: let its status arrive
                self.conn.process.wait(0.5)
            except Exception:  # noqa: BLE001
                pass
        self.error = self._with_report(
            f"link failed at period {k} (t = {k * self.period_s:.6f} s): {exc}")
        self._event("link_failed", {"period": k, "reason": str(exc)})
        raise SessionError(self.error) from exc

    def drain(self) -> None:
        """Collects what the board sent after the last GATES (its last TELEMETRY)."""
        self._drained_period = self.plant.period
        link = self.conn.link
        wait_s = min(self.answer_wait_s, 0.05)
        msg = link.recv(wait_s)
        deadline = time.monotonic() + 0.5    # a chatty board cannot hold teardown
        while msg is not None:
            self.dispatch(msg)
            if time.monotonic() > deadline:
                break
            msg = link.recv(wait_s)

    def attach_mailbox(self, mailbox, on_fault_bits: Callable[[int], None] | None = None) -> None:
        """Connects a Modbus control port's mailbox: requests are applied between periods;
        fault bits written there go to `on_fault_bits` (hil.faults applies them)."""
        self._mailbox = mailbox
        self._on_fault_bits = on_fault_bits

    def _apply_mailbox(self, mailbox) -> None:
        """Applies what the Modbus port's clients wrote, between two periods."""
        req = mailbox.take_requests()
        if req is None:
            return
        # the port checked them; a mailbox written by another hand is checked here too
        limits = self.control_limits
        checked = {}
        for name, value in vars(req).items():
            if value is not None:
                try:
                    checked[name] = limits.request(name, value)
                except ControlInputError as exc:
                    self._refuse_input("mailbox", exc)
        req = type(req)(**checked)
        plant = self.plant
        if req.load_torque_nm is not None:
            plant.load.set_constant(req.load_torque_nm)
            self._event("modbus", {"load_torque_nm": req.load_torque_nm})
        if req.dc_link_voltage_v is not None and req.dc_link_voltage_v > 0:
            plant.set_dc_voltage(req.dc_link_voltage_v)
            self._event("modbus", {"dc_link_voltage_v": req.dc_link_voltage_v})
        change = {}
        if req.run is not None and req.run != self.command_state.enable:
            change["enable"] = req.run
        if req.speed_ref_rpm is not None:
            change["speed_ref_rpm"] = req.speed_ref_rpm
        if change:
            self.send_command(**change)
        if req.fault_bits is not None and self._on_fault_bits is not None:
            self._on_fault_bits(req.fault_bits)

    def _publish(self, mailbox, k: int) -> None:
        from hil.ports.modbus import PlantSnapshot, StateBit

        truth = self.recorder.latest_row("truth")
        f = _TRUTH_INDEX
        state = (StateBit.RUNNING if self.command_state.enable else 0) | \
            (StateBit.BOARD_FAULT if self.faults else 0) | \
            (StateBit.FAULT_INJECTED if self.fault_bits else 0) | \
            (StateBit.REAL_TIME if self.config.mode == "realtime" else 0)
        mailbox.publish(PlantSnapshot(
            truth[f["speed_rpm"]], truth[f["i_a"]], truth[f["i_b"]], truth[f["i_c"]],
            truth[f["torque_nm"]], truth[f["v_dc"]], k, self.rt_stats.get("deadline_misses", 0),
            int(state), truth[f["load_torque_nm"]], self.fault_bits))

    # -------------------------------------------------------------- teardown
    def close(self, reason: str | None = None) -> None:
        if self._closed:
            return
        self._closed = True
        errors = []
        if self.fault_injector is not None:
            self.fault_injector.detach()    # faults stay as they are; nothing lifts them now
        try:
            self.plant.safe_state()
        except Exception as exc:  # noqa: BLE001
            errors.append(exc)
        if self.conn is not None and self.board_hello is not None and \
                self._drained_period != self.plant.period and self.conn.board_alive():
            try:
                self.drain()     # the last period's TELEMETRY, FAULT, STATUS: into the log
            except Exception:  # noqa: BLE001 - a dead line has nothing more to say
                pass
        if self.shoot_throughs > 1 or self.board_faults > 1:
            print(f"hil: {self.shoot_throughs} shoot-through periods, {self.board_faults} board "
                  f"FAULTs in this session (the first of each printed above)", file=sys.stderr)
        if self.conn is not None:
            try:
                self.conn.link.send(Shutdown())
            except Exception:  # noqa: BLE001 - a dead board cannot be told to stop
                pass
            try:
                self.conn.close()
            except Exception as exc:  # noqa: BLE001
                errors.append(exc)
        if self.log is not None:
            try:
                if reason:
                    self._event("session_end", {"reason": reason})
                if self.tap is not None:
                    self.recorder.frames(self.plant.period, self.tap.take_capture())
                if self.conn is not None:
                    self.log.write_json("/link/counters", round(self.plant.t_s * 1e9),
                                        _jsonable(self.link_counters()))
                self.log.close()
            except Exception as exc:  # noqa: BLE001
                errors.append(exc)
        self.cpu_latency.release()
        if errors and reason is None:
            raise errors[0]

    def link_counters(self) -> dict[str, Any]:
        counters = dict(self.conn.link.counters) if self.conn is not None else {}
        counters.update(missed_answers=self.missed_answers, stale_answers=self.stale_answers,
                        resent_samples=self.resent_samples, shoot_throughs=self.shoot_throughs,
                        board_faults=self.board_faults)
        return counters


def _policy(profile, config: SessionConfig) -> SessionPolicy:
    """The profile's session section (SPEC 2.8's defaults) with SessionConfig's overrides."""
    policy = config.policy if config.policy is not None else SessionPolicy.from_profile(profile)
    changes = {key: getattr(config, key) for key in ("watchdog_periods", "watchdog_s",
                                                     "answer_resends", "hello_tries")
               if getattr(config, key) is not None}
    return replace(policy, **changes) if changes else policy


def _f32(value: float) -> bytes:
    return struct.pack("<f", value)


def _ns_text(period_s: float) -> str:
    """A board's control period in ns for a message; a NaN or infinite one as it came."""
    return f"{round(period_s * 1e9)} ns" if math.isfinite(period_s) else f"{period_s} s"


_FAULT_UNITS = {FaultCode.OVERCURRENT: "A", FaultCode.ENCODER_LOSS: "s", FaultCode.DC_LINK: "V",
                FaultCode.WATCHDOG: "s", FaultCode.STALL: "s"}   # FAULT `value` units (SPEC 9.6)


def _fault_text(msg: Fault, period_s: float) -> str:
    try:
        name = FaultCode(msg.code).name
    except ValueError:
        name = "UNKNOWN"
    unit = _FAULT_UNITS.get(msg.code, "")
    if msg.code == FaultCode.NON_FINITE:
        unit = f"({_nonfinite_name(msg.value)})"  # the value codes the quantity (SPEC.md 9.6)
    return (f"period {msg.period} (t = {msg.period * period_s:.6g} s): board FAULT {msg.code} "
            f"{name}, value {msg.value:.4g}{' ' + unit if unit else ''}")


def _nonfinite_name(value: float) -> str:
    try:
        return NonFiniteQuantity(int(value)).name if float(value).is_integer() else "unknown quantity"
    except ValueError:
        return "unknown quantity"


def _name(hello: Hello) -> str:
    name = hello.name
    if isinstance(name, (bytes, bytearray)):
        return bytes(name[: hello.name_len]).decode("utf-8", "replace")
    return str(name)


def _param_status(status: int) -> str:
    return {1: "UNKNOWN", 2: "OUT_OF_RANGE", 3: "READ_ONLY"}.get(status, "error")


def _flatten(d: dict, prefix: str = "") -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, value in d.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict):
            out.update(_flatten(value, name + "."))
        else:
            out[name] = value
    return out


def _jsonable(data: dict) -> dict:
    out = {}
    for key, value in data.items():
        if isinstance(value, (bool, int, float, str)) or value is None:
            out[key] = value
        elif isinstance(value, (list, tuple)):
            out[key] = [v if isinstance(v, (bool, int, float, str)) else str(v) for v in value]
        elif isinstance(value, dict):
            out[key] = _jsonable(value)
        else:
            out[key] = str(value)
    return out


__all__ = ["BenchSession", "SessionConfig", "SessionError", "CommandState", "TRUTH_FIELDS"]
