"""The bench's channels over the Foxglove WebSocket protocol, while a run goes on.

foxglove-sdk's server (Rust, in its own threads) carries `/plant/truth`, `/plant/sensors` and
`/ctrl/telemetry` with the very protobuf schemas the MCAP log has (hil.logs.mcap_writer
fixed_descriptor_set), so a Foxglove layout works on a log and on a live bench alike. The
period loop never waits for a viewer: every `every`-th period (1 kHz by default) the recorder
hands the row over and `Channel.log` queues it in the server, which drops what a slow client
cannot take (its backlog is bounded); the log keeps every period.

A viewer may publish JSON on the client topic `/cmd` (Foxglove's Publish panel):
`{"speed_ref_rpm": 1500}`, `{"enable": true}`, `{"load_torque_nm": 0.5}`,
`{"fault_bits": 4}` (the Modbus fault bits), or `{"pace": "realtime"}` / `{"pace": "fast"}`.
The parameters go into the session's control mailbox (hil.ports.modbus.ControlMailbox), the
very one the Modbus port writes, so the session applies a viewer's change between periods as
it does a Modbus write (and a Modbus read of the holding registers shows it). `pace` is the
viewer's choice of how `hil serve` runs: paced to real time or as fast as it can.

The server binds to 127.0.0.1 unless another host is given, and takes only viewers that open
the URL it prints (its token) from an allowed Origin: hil.live.gate, docs/live.md. /cmd is
applied only from connections the gate let through.
"""
from __future__ import annotations

import json
import os
import secrets
import struct
import threading
from urllib.parse import quote

import foxglove
from foxglove.websocket import Capability, ServerListener

from hil.logs.mcap_writer import FIXED_TYPES, fixed_descriptor_set, tag_varint
from hil.live.gate import FOXGLOVE_ORIGINS, LiveGate
from hil.control_inputs import UNBOUNDED, ControlInputError

COMMAND_TOPIC = "/cmd"
#: Rows (periods handed over by the recorder) given to the server at once; see the module doc.
FLUSH_ROWS = 16
#: /cmd key -> the mailbox's request field (checked by hil.control_inputs); `pace` is the stream's own
COMMAND_KEYS = {"speed_ref_rpm": "speed_ref_rpm", "enable": "run",
                "load_torque_nm": "load_torque_nm", "fault_bits": "fault_bits", "pace": None}
PACES = ("fast", "realtime")
#: A fixed token for scripted viewers (and saved Foxglove connections); unset: a new one a run.
TOKEN_ENV = "HIL_LIVE_TOKEN"


def parse_live_address(text: str, default_port: int = 8765) -> tuple[str, int]:
    """[HOST:]PORT -> (host, port); host defaults to loopback."""
    host, _, port = text.rpartition(":")
    try:
        number = int(port) if port else default_port
    except ValueError:
        raise ValueError(f"live address '{text}': expected [HOST:]PORT") from None
    if not 0 <= number <= 65535:
        raise ValueError(f"live address '{text}': port {number} is out of range")
    return host or "127.0.0.1", number


def payload_struct(fields: list[tuple[str, str]]) -> tuple[struct.Struct, tuple[int, ...]]:
    """The protobuf payload of a fixed-width message (tags and values, in field order) as a
    struct, and the tags to interleave with the values."""
    fmt = "<"
    tags = []
    for number, (_, type_name) in enumerate(fields, start=1):
        _, wire, code = FIXED_TYPES[type_name]
        tag = tag_varint(number, wire)
        fmt += ("B" if len(tag) == 1 else "H") + code
        tags.append(int.from_bytes(tag, "little"))
    return struct.Struct(fmt), tuple(tags)


class _FixedTopic:
    def __init__(self, context, topic: str, message_name: str, fields: list[tuple[str, str]],
                 metadata: dict[str, str]):
        schema = foxglove.Schema(name=message_name, encoding="protobuf",
                                 data=fixed_descriptor_set(message_name, fields))
        self.channel = foxglove.Channel(topic, schema=schema, message_encoding="protobuf",
                                        context=context, metadata=metadata)
        self._struct, tags = payload_struct(fields)
        self._args = [0] * (2 * len(tags))
        self._args[0::2] = tags

    def log(self, log_time_ns: int, values) -> None:
        args = self._args
        args[1::2] = values
        self.channel.log(self._struct.pack(*args), log_time=log_time_ns)


class _Listener(ServerListener):
    """Collects what viewers publish on /cmd; everything else is ignored (the base class's
    no-op callbacks: without them the server prints 'Callback failed' on each subscribe)."""

    def __init__(self, stream: "LiveStream", auth_topic: str):
        self._stream = stream
        self._auth_topic = auth_topic
        self._topics: dict[tuple[int, int], str] = {}
        self._admitted: set[int] = set()     # client ids the gate let through

    def on_client_advertise(self, client, channel) -> None:
        if channel.topic == self._auth_topic:
            self._admitted.add(client.id)
            return
        self._topics[(client.id, channel.id)] = channel.topic

    def on_client_unadvertise(self, client, client_channel_id: int) -> None:
        self._topics.pop((client.id, client_channel_id), None)

    def on_message_data(self, client, client_channel_id: int, data: bytes) -> None:
        if self._topics.get((client.id, client_channel_id)) == COMMAND_TOPIC:
            if client.id in self._admitted:
                self._stream._command(data)
            else:                            # on the SDK's own port, past the gate
                self._stream._refused(f"{COMMAND_TOPIC} from a connection that did not come "
                                      f"through the gate; not applied", command=True)


class LiveStream:
    """A Foxglove WebSocket server carrying the run; `every` periods between two rows sent."""

    def __init__(self, host: str = "127.0.0.1", port: int = 8765, *, period_s: float,
                 rate_hz: float = 1000.0, mode: str = "lockstep", name: str = "hil-bench",
                 pace: str = "fast", token: str | None = None,
                 origins: tuple[str, ...] = FOXGLOVE_ORIGINS):
        from plant_rt import TRUTH_FIELDS

        from hil.logs.recorder import SENSOR_FIELDS, TELEMETRY_FIELDS

        self.every = max(1, round(1.0 / (rate_hz * period_s)))
        self.period_s = period_s
        self.errors: list[str] = []
        # (log time ns, values) per channel, oldest first, until the next flush
        self._truth_rows: list[tuple] = []
        self._sensor_rows: list[tuple] = []
        self._telemetry_rows: list[tuple] = []
        self.flushes = 0                     # batches handed to the server (tests count them)
        self._mailbox = None
        self.pace = pace
        self.commands_taken = 0              # /cmd messages accepted (tests count them)
        self.commands_refused = 0            # /cmd messages refused, whatever the reason
        self._limits = UNBOUNDED             # hil.control_inputs: the ranges
        self._lock = threading.Lock()
        self._context = foxglove.Context()
        # Lockstep runs as fast as it can: the viewer is told that simulated time is not wall time.
        metadata = {"clock": mode, "period_s": repr(period_s),
                    "decimation": str(self.every),
                    "note": ("simulated time; lockstep runs faster than real time"
                             if mode == "lockstep" else "wall-clock time")}
        self.truth = _FixedTopic(self._context, "/plant/truth", "hil.PlantTruth",
                                 [(f, "double" if f == "t_s" else "float") for f in TRUTH_FIELDS],
                                 metadata)
        self.sensors = _FixedTopic(self._context, "/plant/sensors", "hil.SensorSample",
                                   [("period", "fixed32")] + [(f, "fixed32") for f in SENSOR_FIELDS],
                                   metadata)
        self.telemetry = _FixedTopic(self._context, "/ctrl/telemetry", "hil.Telemetry",
                                     [("period", "fixed32")] + [(f, "fixed32" if i < 4 else "float")
                                                                for i, f in enumerate(TELEMETRY_FIELDS)],
                                     metadata)
        # The SDK's server on an ephemeral loopback port, the gate on the one asked for.
        self.token = token or os.environ.get(TOKEN_ENV) or secrets.token_urlsafe(18)
        auth_topic = f"/hil/gate/{secrets.token_hex(16)}"
        self.server = foxglove.start_server(
            name=name, host="127.0.0.1", port=0, context=self._context,
            capabilities=[Capability.ClientPublish], supported_encodings=["json"],
            server_listener=_Listener(self, auth_topic), message_backlog_size=1024)
        try:
            self.gate = LiveGate(host, port, self.server.port, self.token, origins, auth_topic,
                                 on_refusal=self._refused)
        except BaseException:
            self.server.stop()
            raise
        self.host, self.port = host, self.gate.port

    def follow(self, period_s: float) -> "LiveStream":
        """The next session's control period (one server serves every plan of a `hil run`)."""
        self.flush()                         # the last plan's tail goes out before the next
        rate_hz = 1.0 / (self.every * self.period_s)
        self.period_s = period_s
        self.every = max(1, round(1.0 / (rate_hz * period_s)))
        return self

    @property
    def url(self) -> str:
        """The address to open (with the token: the gate refuses it without)."""
        return f"ws://{self.host}:{self.port}/?token={self.token}"

    @property
    def app_url(self) -> str:
        """Foxglove's web app opening this stream."""
        return ("https://app.foxglove.dev/?ds=foxglove-websocket&ds.url="
                + quote(self.url, safe=""))

    # ------------------------------------------------------------- from the recorder
    def period(self, k: int, truth: tuple, sample) -> None:
        t_ns = round(k * self.period_s * 1e9)
        self._truth_rows.append((t_ns, truth))
        self._sensor_rows.append((t_ns, (k, sample.adc_i1, sample.adc_i2, sample.adc_vdc,
                                         sample.encoder, sample.status)))
        if len(self._truth_rows) >= FLUSH_ROWS:
            self.flush()

    def telemetry_row(self, row: tuple) -> None:
        self._telemetry_rows.append((round(row[0] * self.period_s * 1e9), row))

    def flush(self) -> None:
        """Hands every kept row to the server, back to back, channel by channel; the rows of
        a channel no viewer subscribes to are dropped here, before any packing."""
        sent = 0
        for topic, rows in ((self.truth, self._truth_rows), (self.sensors, self._sensor_rows),
                            (self.telemetry, self._telemetry_rows)):
            if rows and topic.channel.has_sinks():
                log = topic.log
                for t_ns, values in rows:
                    log(t_ns, values)
                sent += len(rows)
            rows.clear()
        if sent:
            self.flushes += 1

    # ------------------------------------------------------------- from the viewers
    def attach_mailbox(self, mailbox, limits=None) -> None:
        """Where viewers' parameter changes go: a ControlMailbox (anything with
        request(**fields) -> bool), and the ranges they must lie in (a ControlLimits, made
        from the bench profile; None: finite and float32 only). Without a mailbox, /cmd
        parameters are refused with an error (a `hil run` takes its stimuli from the plan)."""
        self._mailbox = mailbox
        self._limits = limits if limits is not None else UNBOUNDED

    def _command(self, data: bytes) -> None:
        try:
            msg = json.loads(data)
            if not isinstance(msg, dict):
                raise ValueError("expected a JSON object")
            request = {}
            pace = None
            for key, value in msg.items():
                if key not in COMMAND_KEYS:
                    raise ValueError(f"unknown key '{key}' (known: {', '.join(COMMAND_KEYS)})")
                field = COMMAND_KEYS[key]
                if field is None:
                    if value not in PACES:
                        raise ValueError(f"'pace': expected one of {', '.join(PACES)}, got {value!r}")
                    pace = value
                else:
                    try:
                        request[field] = self._limits.request(field, value)
                    except ControlInputError as exc:
                        raise ValueError(f"'{key}': {exc.why}, got {value!r}") from None
            if request and self._mailbox is None:
                raise ValueError("this run takes no parameters from viewers (hil serve does)")
            if request and not self._mailbox.request(**request):
                raise ValueError("the control mailbox stayed busy for a second; not applied")
        except (ValueError, TypeError) as exc:
            with self._lock:
                self.errors.append(f"{COMMAND_TOPIC}: {exc}; not applied")
                self.commands_refused += 1
            return
        with self._lock:
            if pace is not None:
                self.pace = pace
            self.commands_taken += 1

    def _refused(self, text: str, command: bool = False) -> None:
        """A connection or message the gate or the listener turned away (for the console)."""
        with self._lock:
            self.errors.append(text)
            self.commands_refused += command

    def take_errors(self) -> list[str]:
        """Errors in what viewers published, and connections the gate refused, since the
        last call (for the console)."""
        self.gate.poll()
        with self._lock:
            out, self.errors = self.errors, []
        return out

    def close(self) -> None:
        self.flush()
        self.gate.stop()
        self.server.stop()
