"""A bench session: a plant, a board on a link, a clock and a log.

The session is the only place where periods happen. Per period, in lockstep:
the plant's sensors are sampled at t_k and sent as SAMPLE k; the board's GATES k
is awaited (for ``answer_timeout_s`` of wall time); the plant integrates
[t_k, t_k+1] with it (holding the previous gates when none came). Everything
that crossed is recorded in memory (for checks) and in the MCAP log.

Teardown always runs (OpenHTF's lesson): whatever ends a run — its end, a
failed check, a dead board, Ctrl-C — the inverter goes to its safe state
(all switches off, the motor coasts through the diodes), SHUTDOWN is sent, the
board's process is stopped and the log is closed readable.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Callable

from plant_rt import Plant, TRUTH_FIELDS
from protocol.messages import (
    PROTOCOL_VERSION, Command, Fault, Gates, Duty, Hello, ParamGet, ParamId, ParamSet,
    ParamValue, Role, Sample, Shutdown, SpeedSource, Status, Telemetry,
)

from hil.links.registry import BoardConnection, connect
from hil.logs.recorder import COMMAND_FIELDS, Recorder
from hil.session.board_params import board_parameters
from hil.session.cpu_latency import CpuLatencyHold
from hil.session.errors import SessionError
from hil.session.link_tap import LinkTap, tappable
from hil.session.realtime import run_realtime
from hil.session.watchdog import Watchdog, await_answer

RPM_PER_RAD_S = 60.0 / (2.0 * math.pi)
_TRUTH_INDEX = {name: i for i, name in enumerate(TRUTH_FIELDS)}


@dataclass
class SessionConfig:
    link: str = "stub"
    mode: str = "lockstep"                  # lockstep | realtime
    log_path: Path | None = None
    seed: int = 0
    # Consecutive periods without a GATES answer before the watchdog safe-states the plant,
    # and (when set) the wall-clock time without one, whichever comes first.
    watchdog_periods: int = 20
    watchdog_s: float | None = None
    hello_timeout_s: float | None = None    # None: the link's own default
    answer_timeout_s: float | None = None
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
        self.faults: list[Fault] = []
        self.events: list[tuple[float, str, dict]] = []
        self.missed_answers = 0
        self.watchdog = Watchdog(self.config.watchdog_periods, self.config.watchdog_s)
        self.stale_answers = 0
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

            self.log = McapLog(cfg.log_path, metadata=self._metadata())
            self.recorder.attach_log(self.log)
        self.conn = connect(cfg.link)
        if cfg.tap_link and tappable(self.conn.link):
            self.tap = self.conn.link = LinkTap(self.conn.link, seed=cfg.seed)
        if cfg.hello_timeout_s is not None:
            self.conn.hello_timeout_s = cfg.hello_timeout_s
        if cfg.answer_timeout_s is not None:
            self.conn.answer_timeout_s = cfg.answer_timeout_s
        self._handshake()
        self._push_parameters(board_parameters(self.profile))
        self.send_command()

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
        }
        meta.update(self.config.metadata)
        return meta

    def _await(self, predicate: Callable[[Any], bool], timeout_s: float, what: str):
        """Receives until a message satisfies predicate within one deadline; other messages
        are dispatched and do not extend it."""
        msg = await_answer(self.conn.link, predicate, timeout_s, self.dispatch)
        if msg is not None:
            return msg
        if not self.conn.board_alive():
            raise SessionError(f"board on '{self.config.link}' exited with status "
                               f"{self.conn.board_exit_status()} while waiting for {what}")
        raise SessionError(f"no {what} from the board on '{self.config.link}' within "
                           f"{timeout_s:g} s")

    def _handshake(self) -> None:
        link = self.conn.link
        link.send(Hello(proto_version=PROTOCOL_VERSION, role=int(Role.BENCH), capabilities=0,
                        control_period_ns=round(self.period_s * 1e9), name_len=len(b"hil-bench"),
                        name=b"hil-bench"))
        hello = self._await(lambda m: isinstance(m, Hello), self.conn.hello_timeout_s, "HELLO")
        if hello.proto_version != PROTOCOL_VERSION:
            raise SessionError(
                f"board on '{self.config.link}' speaks protocol version {hello.proto_version}, "
                f"the bench speaks version {PROTOCOL_VERSION}")
        self.board_hello = hello
        self._event("hello", {"board": _name(hello), "proto_version": hello.proto_version,
                              "capabilities": hello.capabilities,
                              "control_period_ns": hello.control_period_ns})

    def _push_parameters(self, params: dict[str, float]) -> None:
        for name, value in params.items():
            self.param_set(name, value)

    def param_set(self, name: str, value: float) -> float:
        """PARAM_SET then PARAM_GET: returns the value the board reads back (float32)."""
        pid = ParamId[name.upper()]
        link = self.conn.link
        link.send(ParamSet(id=int(pid), value=float(value)))
        answer = self._await(lambda m: isinstance(m, ParamValue) and m.id == pid,
                             self.conn.hello_timeout_s, f"PARAM_VALUE for {name}")
        if answer.status != 0:
            raise SessionError(f"board refused parameter {name} = {value:g} "
                               f"(status {answer.status}: {_param_status(answer.status)})")
        link.send(ParamGet(id=int(pid)))
        readback = self._await(lambda m: isinstance(m, ParamValue) and m.id == pid,
                               self.conn.hello_timeout_s, f"PARAM_VALUE readback of {name}")
        if not math.isclose(readback.value, value, rel_tol=1e-6, abs_tol=1e-12):
            raise SessionError(f"parameter {name}: set {value!r}, board reads back {readback.value!r}")
        self.board_params[name] = readback.value
        self._event("param", {"name": name, "value": readback.value})
        return readback.value

    # -------------------------------------------------------------- commands
    def send_command(self, **changes: Any) -> None:
        """Updates the command state (engineering units) and sends COMMAND."""
        unknown = set(changes) - set(COMMAND_FIELDS)
        if unknown:
            raise ValueError(f"unknown command field(s): {', '.join(sorted(unknown))}")
        self.command_state = replace(self.command_state, **changes)
        msg = self.command_state.to_message(self.board_params.get("flux_ref_wb", 0.0))
        self.conn.link.send(msg)
        self.recorder.command(self.plant.period, self.command_state.row())
        self._event("command", dict(changes))

    @property
    def board_name(self) -> str:
        return _name(self.board_hello) if self.board_hello is not None else ""

    def _event(self, kind: str, data: dict) -> None:
        t = self.plant.period * self.period_s
        self.events.append((t, kind, data))
        if self.log is not None:
            self.log.write_json("/plan/events", round(t * 1e9), {"t_s": t, "kind": kind, **_jsonable(data)})

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
        elif t is Status:
            self.recorder.step_value("ctrl.fault_code", msg.period, msg.fault_code)
            self._event("board_status", {"state": msg.state, "fault_code": msg.fault_code,
                                         "period": msg.period})
        elif t is Gates or t is Duty:
            self.stale_answers += 1
        # HEARTBEAT, late PARAM_VALUEs: nothing to do beyond the raw-frame log

    # --------------------------------------------------------------- running
    def run_periods(self, count: int, stop: Callable[[], bool] | None = None) -> int:
        """Advances up to ``count`` periods (lockstep or real time); returns how many ran."""
        if self.config.mode == "realtime":
            return run_realtime(self, count, stop)
        return self._run_lockstep(count, stop)

    def _run_lockstep(self, count: int, stop: Callable[[], bool] | None) -> int:
        plant = self.plant
        link = self.conn.link
        recorder = self.recorder
        dispatch = self.dispatch
        answer_timeout = self.conn.answer_timeout_s
        watchdog = self.watchdog
        mailbox = self._mailbox
        on_period = self.on_period
        publish_every = self.publish_every
        tap = self.tap
        clock = time.monotonic
        for done in range(count):
            if mailbox is not None and mailbox.pending:
                self._apply_mailbox(mailbox)
            sample = plant.sample()
            k = sample.period
            if tap is not None:
                tap.tick(k)
                if k % publish_every == 0:
                    recorder.frames(k, tap.take_capture())
            recorder.period(k, plant.truth(), sample)
            gates = duty = None
            try:
                link.send(Sample(k, sample.adc_i1, sample.adc_i2, sample.adc_vdc, sample.encoder,
                                 sample.status))
                # One deadline per SAMPLE: other traffic is handled but never extends it.
                deadline = clock() + answer_timeout
                wait = answer_timeout
                msg = link.recv(wait)
                while msg is not None:
                    t = type(msg)
                    if t is Gates:
                        if msg.period == k:
                            gates = msg.gates
                            break
                        self.stale_answers += 1
                    elif t is Duty:
                        if msg.period == k:
                            d = msg.duty
                            duty = (d[0] / 65535.0, d[1] / 65535.0, d[2] / 65535.0)
                            break
                        self.stale_answers += 1
                    else:
                        dispatch(msg)
                    if wait > 0.0:
                        wait = deadline - clock()
                        if wait <= 0.0:
                            wait = -1.0       # past the deadline: take only what is queued
                    if wait < 0.0:
                        msg = link.recv(0.0)
                        if msg is not None and clock() > deadline + answer_timeout:
                            break             # a flood: the period is lost
                    else:
                        msg = link.recv(wait)
            except (OSError, ValueError) as exc:  # LinkError is an OSError: the line is gone
                self._link_failed(k, exc)
            if gates is None and duty is None:
                self.missed_answers += 1
                why = watchdog.missed()
                if why is not None:
                    plant.safe_state()
                    if not self.conn.board_alive():
                        why = ("the board process exited with status "
                               f"{self.conn.board_exit_status()}")
                    self.error = f"watchdog at period {k} (t = {k * self.period_s:.6f} s): {why}"
                    self._event("watchdog", {"period": k, "reason": why})
                    raise SessionError(self.error)
                plant.step(None)
            else:
                watchdog.answered()
                if duty is None:
                    plant.step(gates)
                else:
                    plant.step(duty=duty)
            if on_period is not None:
                on_period(k)
            if mailbox is not None and k % publish_every == 0:
                self._publish(mailbox, k)
            if stop is not None and stop():
                return done + 1
        return count

    @property
    def consecutive_misses(self) -> int:
        return self.watchdog.consecutive

    def _link_failed(self, k: int, exc: Exception) -> None:
        self.plant.safe_state()
        status = self.conn.board_exit_status()
        board = f"; the board process exited with status {status}" if status is not None else ""
        self.error = f"link failed at period {k} (t = {k * self.period_s:.6f} s): {exc}{board}"
        self._event("link_failed", {"period": k, "reason": str(exc)})
        raise SessionError(self.error) from exc

    def drain(self) -> None:
        """Collects what the board sent after the last GATES (its last TELEMETRY)."""
        link = self.conn.link
        wait_s = min(self.conn.answer_timeout_s, 0.05)
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
        plant = self.plant
        if req.load_torque_nm is not None:
            plant.load.set_constant(req.load_torque_nm)
            self._event("modbus", {"load_torque_nm": req.load_torque_nm})
        if req.dc_link_voltage_v is not None and req.dc_link_voltage_v > 0:
            plant.set_dc_voltage(req.dc_link_voltage_v)
            self._event("modbus", {"dc_link_voltage_v": req.dc_link_voltage_v})
        if req.run is not None and req.run != self.command_state.enable:
            self.send_command(enable=req.run)
        if req.fault_bits is not None and self._on_fault_bits is not None:
            self._on_fault_bits(req.fault_bits)

    def _publish(self, mailbox, k: int) -> None:
        from hil.ports.modbus import PlantSnapshot, StateBit

        truth = self.recorder.truth_rows[-1]
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
        counters.update(missed_answers=self.missed_answers, stale_answers=self.stale_answers)
        return counters


def _name(hello: Hello) -> str:
    name = hello.name
    if isinstance(name, (bytes, bytearray)):
        return bytes(name[: hello.name_len]).decode("utf-8", "replace")
    return str(name)


def _param_status(status: int) -> str:
    return {1: "unknown parameter", 2: "out of range", 3: "read-only"}.get(status, "error")


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
