"""``hil probe LINK``: what the wire to a board allows, measured (docs/adapters.md).

HELLO, then a bounded train of SAMPLEs, each awaiting its answer (GATES, DUTY or DUTY_LEGS of
its period) before the next goes: the lockstep exchange itself. The report gives the round
trip's distribution, the lockstep rate it allows (1 / mean round trip), the shortest real-time
period it could hold (the 99th percentile: an answer must be back before the next tick), what
the port is (Linux sysfs: driver, FTDI latency timer, low-latency flag, USB speed, CAN
bitrate), the figures the wire model expects for such an adapter, and when they are poor the
cause and the fix. ``--set-latency-timer MS`` writes an FTDI port's latency timer first.

A board that advertises the SENSOR_SET capability gets SAMPLE_SENSORS instead (SPEC 6.13): its
set is read after HELLO (PARAM_GET of SENSOR_SET under SPEC 2.8.3's wait and tries), checked as
the session checks it, and reported.

A link with ``wire=NAME`` (``stub-pty?wire=ftdi-16ms``) is probed through the link tap with
its frames really held to the model's arrival times, so the probe measures the model.
"""
from __future__ import annotations

import math
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

from protocol.messages import (CAP_SENSOR_SET, PROTOCOL_VERSION, Duty, DutyLegs, Fault, FaultCode,
                               Gates, Hello, ParamGet, ParamValue, Role, Sample, SampleSensors,
                               Shutdown)

from hil.links import adapters
from hil.links.adapters import AdapterInfo, Advice

DEFAULT_SAMPLES = 200
HELLO_WAIT_S = 2.0
HELLO_TRIES = 3
ANSWER_WAIT_S = 1.0            # per SAMPLE: past the FTDI's largest latency timer (255 ms)
MAX_MISSES = 5                 # consecutive unanswered SAMPLEs end the train
DEFAULT_PERIOD_NS = 50_000     # the paper's period, announced in the bench's HELLO
PARAM_WAIT_S = 1.0             # SPEC 2.8.3's param_wait_s, per PARAM_GET of SENSOR_SET
PARAM_TRIES = 3                # and its param_tries
#: A SAMPLE_SENSORS field's value in the train: a motor at rest at theta_e = 0, 25 degC, with
#: SPEC 1.1's default scalings, as SAMPLE's train is (mid-scale currents and DC link,
#: encoder 0): Hall word 001 (theta_e in (-30, 30) deg), terminals all equal so no
#: comparator is above the virtual neutral, resolver sin at its offset and cos at offset + the
#: default 1800-count amplitude, 250 counts = 25 degC at 0.1 degC per count.
SENSOR_TRAIN_VALUES = {"adc_ia": 2048, "adc_ib": 2048, "adc_ic": 2048, "adc_vdc": 2048,
                       "encoder": 0, "hall": 0b001, "adc_va": 2048, "adc_vb": 2048,
                       "adc_vc": 2048, "bemf_comparators": 0, "adc_resolver_sin": 2048,
                       "adc_resolver_cos": 2048 + 1800, "adc_temperature": 250}
_ANSWERS = (Gates, Duty, DutyLegs)


@dataclass
class ProbeReport:
    link: str
    board: str
    adapter: AdapterInfo
    advice: Advice
    round_trips_s: list[float] = field(default_factory=list)
    samples_sent: int = 0
    missing: int = 0
    expected: dict = field(default_factory=dict)   # the wire model's figures, if one applies
    sensor_set: int | None = None   # the board's SENSOR_SET; None: a SAMPLE board
    faults: list[dict] = field(default_factory=list)   # the FAULTs the board sent in the train

    def summary(self) -> dict:
        import numpy as np

        rtt = np.asarray(self.round_trips_s, dtype=float)
        out = {"link": self.link, "board": self.board, "samples_sent": self.samples_sent,
               "answered": int(rtt.size), "missing": self.missing,
               "adapter": self.adapter.metadata(),
               "cause": self.advice.cause, "fix": self.advice.fix, "poor": self.advice.poor,
               "expected": self.expected, "sensor_set": None, "faults": self.faults}
        if self.sensor_set is not None:
            from hil.boards.board_file import sensor_set_names

            out["sensor_set"] = {"mask": self.sensor_set,
                                 "sensors": list(sensor_set_names(self.sensor_set))}
        if rtt.size:
            us = rtt * 1e6
            out["round_trip_us"] = {"min": float(us.min()), "p50": float(np.percentile(us, 50)),
                                    "p90": float(np.percentile(us, 90)),
                                    "p99": float(np.percentile(us, 99)),
                                    "max": float(us.max()), "mean": float(us.mean())}
            out["lockstep_rate_hz"] = float(1.0 / rtt.mean())
            out["shortest_realtime_period_us"] = float(np.percentile(us, 99))
        return out


class ProbeError(RuntimeError):
    pass


def probe(spec: str, samples: int = DEFAULT_SAMPLES, sysfs_root: Path | None = None,
          period_ns: int = DEFAULT_PERIOD_NS, set_latency_timer_ms: int | None = None,
          answer_wait_s: float = ANSWER_WAIT_S, hello_wait_s: float = HELLO_WAIT_S,
          param_wait_s: float = PARAM_WAIT_S) -> ProbeReport:
    """Probes the board on ``spec``; raises ProbeError naming what failed."""
    from hil.links.registry import connect, split_wire
    from hil.session.link_tap import LinkTap, tappable

    if samples < 1:
        raise ProbeError(f"probe: --samples must be at least 1, got {samples}")
    root = adapters.SYSFS_ROOT if sysfs_root is None else Path(sysfs_root)
    bare, wire = split_wire(spec)
    info = adapters.inspect_link(bare, root, wire=wire)
    if set_latency_timer_ms is not None:
        print(f"hil probe: {adapters.set_latency_timer(info, set_latency_timer_ms, root)}",
              file=sys.stderr)
    conn = connect(spec)
    try:
        link = conn.link
        if tappable(link):      # frames held to the modelled wire's arrival, if it has one
            link = conn.link = LinkTap(link, wire=conn.wire, delay_frames=True)
        elif conn.wire is not None:
            raise ProbeError(f"probe '{spec}': wire={conn.wire.name} needs a byte link")
        inner = getattr(link, "link", link)
        descriptor = getattr(inner, "descriptor", None)
        if info.kind not in ("pty", "process"):
            info.low_latency = adapters.read_low_latency(descriptor() if descriptor else None)
        hello = _hello(link, period_ns, spec, hello_wait_s)
        report = ProbeReport(spec, _name(hello), info, adapters.advice(info))
        if hello.capabilities & CAP_SENSOR_SET:
            report.sensor_set = _sensor_set(link, spec, param_wait_s)
        _train(link, samples, answer_wait_s, report)
        try:
            link.send(Shutdown())
        except OSError:
            pass
    finally:
        conn.close()
    model = info.expected_wire()
    if model is not None:
        report.expected = {"wire_model": model.describe(),
                           "lockstep_rate_hz": model.lockstep_rate_hz(),
                           "round_trip_us": model.lockstep_period_s() * 1e6,
                           "shortest_realtime_period_us":
                               model.shortest_realtime_period_s() * 1e6}
    return report


def _hello(link, period_ns: int, spec: str, wait_s: float) -> Hello:
    mine = Hello(proto_version=PROTOCOL_VERSION, role=int(Role.BENCH), capabilities=0,
                 control_period_ns=period_ns, name=b"hil-probe")
    for _ in range(HELLO_TRIES):
        link.send(mine)
        deadline = time.monotonic() + wait_s
        while (left := deadline - time.monotonic()) > 0:
            msg = link.recv(left)
            if isinstance(msg, Hello):
                if msg.proto_version != PROTOCOL_VERSION:
                    raise ProbeError(f"probe '{spec}': the board speaks protocol version "
                                     f"{msg.proto_version}, the bench {PROTOCOL_VERSION}")
                return msg
    raise ProbeError(f"probe '{spec}': no HELLO from the board after {HELLO_TRIES} tries of "
                     f"{wait_s:g} s")


def _sensor_set(link, spec: str, wait_s: float) -> int:
    """The board's SENSOR_SET (PARAM_GET, SPEC 2.8.3's wait and tries), checked as the session
    checks it; ProbeError naming the parameter and its value otherwise."""
    from hil.session.errors import SessionError
    from hil.session.sensor_set import SENSOR_SET_ID, sensor_set_of_answer

    where = f"probe '{spec}': the board"
    answer = None
    for _ in range(PARAM_TRIES):
        link.send(ParamGet(id=SENSOR_SET_ID))
        deadline = time.monotonic() + wait_s
        while answer is None and (left := deadline - time.monotonic()) > 0:
            msg = link.recv(left)
            if isinstance(msg, ParamValue) and msg.id == SENSOR_SET_ID:
                answer = msg
        if answer is not None:
            break
    if answer is None:
        raise ProbeError(f"{where} advertises SENSOR_SET but sent no PARAM_VALUE for parameter "
                         f"sensor_set (id {SENSOR_SET_ID}) after {PARAM_TRIES} tries of "
                         f"{wait_s:g} s")
    if answer.status != 0:
        raise ProbeError(f"{where} advertises SENSOR_SET but refused PARAM_GET of parameter "
                         f"sensor_set (id {SENSOR_SET_ID}, status {answer.status})")
    try:
        return sensor_set_of_answer(answer.value, where)
    except SessionError as e:
        raise ProbeError(str(e)) from None


def _stimulus(k: int, sensor_set: int | None):
    """Period k's SAMPLE, or SAMPLE_SENSORS with the fields of the board's set."""
    if sensor_set is None:
        return Sample(k, 2048, 2048, 2048, 0, 0)
    from hil.boards.sensor_fields import fields_of_set

    values = {f: SENSOR_TRAIN_VALUES[f] for f in fields_of_set(sensor_set)}
    return SampleSensors(k, sensor_set, 0, **values)


def _train(link, samples: int, answer_wait_s: float, report: ProbeReport) -> None:
    """SAMPLE k (SAMPLE_SENSORS to a sensor-set board), its answer, SAMPLE k+1: a motor at
    rest (SENSOR_TRAIN_VALUES)."""
    clock = time.perf_counter
    misses = 0
    for k in range(samples):
        stimulus = _stimulus(k, report.sensor_set)
        sent = clock()
        link.send(stimulus)
        report.samples_sent += 1
        deadline = sent + answer_wait_s
        got = None
        while got is None and (left := deadline - clock()) > 0:
            msg = link.recv(left)
            if isinstance(msg, _ANSWERS) and msg.period == k:
                got = clock()
            elif isinstance(msg, Fault):
                report.faults.append(_fault(msg))
        if got is None:
            report.missing += 1
            misses += 1
            if misses >= MAX_MISSES:
                break
            continue
        misses = 0
        report.round_trips_s.append(got - sent)


def _fault(msg: Fault) -> dict:
    """A FAULT as plain data: its period, code, the code's name, its value (None if not finite:
    the report stays JSON)."""
    try:
        name = FaultCode(msg.code).name
    except ValueError:
        name = "UNKNOWN"
    value = float(msg.value)
    return {"period": int(msg.period), "code": int(msg.code), "name": name,
            "value": value if math.isfinite(value) else None}


def _name(hello: Hello) -> str:
    name = hello.name
    if isinstance(name, (bytes, bytearray)):
        return bytes(name[: hello.name_len]).decode("utf-8", "replace")
    return str(name)


def format_report(summary: dict) -> str:
    lines = [f"probe {summary['link']}: board '{summary['board']}', {summary['answered']} of "
             f"{summary['samples_sent']} SAMPLEs answered"]
    sensor_set = summary.get("sensor_set")
    if sensor_set:
        lines[0] = lines[0].replace(" SAMPLEs ", " SAMPLE_SENSORS ")
        lines.append(f"  sensors   {', '.join(sensor_set['sensors']) or 'none'} "
                     f"(SENSOR_SET 0x{sensor_set['mask']:04x}, sent SAMPLE_SENSORS)")
    adapter = summary["adapter"]
    settings = ", ".join(f"{k} {v}" for k, v in adapter.items()
                         if k not in ("port", "description", "kind") and v
                         and not k.startswith("modelled."))
    lines.append(f"  port      {adapter.get('description', '')}" +
                 (f" [{settings}]" if settings else ""))
    rtt = summary.get("round_trip_us")
    if rtt:
        lines.append("  round trip  " + "  ".join(f"{k} {_us(v)}" for k, v in rtt.items()))
        lines.append(f"  lockstep  {summary['lockstep_rate_hz']:.0f} periods/s "
                     f"(1 s of a 20 kHz plan: {20_000 / summary['lockstep_rate_hz']:.0f} s)")
        lines.append(f"  real time shortest period it could hold: "
                     f"{_us(summary['shortest_realtime_period_us'])} (p99 round trip)")
    expected = summary.get("expected")
    if expected:
        lines.append(f"  expected  {expected['wire_model']}: {expected['lockstep_rate_hz']:.0f} "
                     f"periods/s, real-time period >= "
                     f"{_us(expected['shortest_realtime_period_us'])}")
    for fault in summary.get("faults", []):
        value = "" if fault["value"] is None else f", value {fault['value']:g}"
        lines.append(f"  board     FAULT {fault['code']} {fault['name']} at period "
                     f"{fault['period']}{value}")
    lines.append(f"  {'cause' if summary['poor'] else 'note '}     {summary['cause']}")
    if summary["fix"]:
        lines.append(f"  fix       {summary['fix']}")
    return "\n".join(lines)


def _us(us: float) -> str:
    if not math.isfinite(us):
        return str(us)
    return f"{us:.0f} µs" if us < 10_000 else f"{us / 1000:.1f} ms"


def add_arguments(parser) -> None:
    parser.add_argument("link", help="the board's link, e.g. serial:/dev/ttyUSB0?baud=2000000, "
                                     "can:socketcan:can0, stub-pty?wire=ftdi-16ms")
    parser.add_argument("--samples", type=int, default=DEFAULT_SAMPLES,
                        help=f"SAMPLEs in the train (default {DEFAULT_SAMPLES})")
    parser.add_argument("--set-latency-timer", type=int, metavar="MS",
                        help="write an FTDI port's latency_timer (1..255 ms) before probing")
    parser.add_argument("--sysfs-root", type=Path, help="sysfs root (default /sys)")
    parser.add_argument("--json", action="store_true", help="print the report as JSON")


def probe_command(args) -> int:
    import json

    report = probe(args.link, samples=args.samples, sysfs_root=args.sysfs_root,
                   set_latency_timer_ms=args.set_latency_timer)
    summary = report.summary()
    print(json.dumps(summary, indent=2) if args.json else format_report(summary))
    return 0 if summary["answered"] else 2
