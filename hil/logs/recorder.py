"""Keeps every period's plant truth, sensor values, telemetry and commands.

A period's rows go straight into a preallocated float64 stage: one C call from Python
(protocol.ccodec.stage_period, stage_telemetry), or written by the C period loop itself (no
Python object kept).
Every `LOG_BATCH_PERIODS` periods the stage is sealed: copied into blocks the run keeps for its
checks at its end, and emptied in place. With a log, the new blocks go to it at
the same time (`FixedChannel.write_many`, numpy columns into the open chunk) instead of one
Python call per message (cost per period: `python -m bench mcap_logging`). The log's crash
bound grows by the batch: a SIGKILL loses the open chunk and at most the last 256 periods
(12.8 ms at 50 us); flush() and close() write the batch first. Signals are
aligned on the sample instant t_k = k * T: the plant truth recorded for period
k is the state the sensors sampled, and the telemetry of period k is what the
board computed from that sample.
"""
from __future__ import annotations

import math
from operator import attrgetter

import numpy as np

from plant_rt import TRUTH_FIELDS
from protocol import ccodec
from protocol.messages import Telemetry

from hil.boards.sensor_fields import ALL_SENSOR_FIELDS, SAMPLE_GROUP, WINDING_TEMPERATURE_SIGNAL

#: Periods between two batched writes of the full-rate channels to the log.
LOG_BATCH_PERIODS = 256

SENSOR_FIELDS = ("adc_i1", "adc_i2", "adc_vdc", "encoder", "status")
TELEMETRY_FIELDS = ("sector", "speed_source", "state", "gates", "speed_feedback_rad_s",
                    "speed_encoder_rad_s", "speed_raw_rad_s", "speed_lpf_rad_s", "speed_ekf_rad_s",
                    "flux_angle_rad", "ekf_angle_rad", "flux_mag_wb", "torque_est_nm",
                    "torque_ref_nm", "rotor_pos_conv_rad", "rotor_pos_ekf_rad")
COMMAND_FIELDS = ("enable", "speed_source", "speed_ref_rpm", "torque_mode", "torque_ref_nm",
                  "flux_ref_wb")
#: Step signals every run has (0 until they change): the board's latched fault code (FAULT,
#: STATUS), the Modbus bits of the injected faults in effect (hil/faults/injector.py), and the
#: board's state from STATUS and whether it is ready (hil/session/board_state.py), and the leg
#: enables of a DUTY_LEGS board's answers (0 on every other board).
STEP_SIGNALS = ("ctrl.fault_code", "fault.active_bits", "board.state", "board.ready",
                "ctrl.leg_enable")

#: Where a run log keeps each group of signals: plan name ``group.field`` -> that topic's
#: ``field``. A step signal ``board.state`` is the ``value`` of topic /step/board.state,
#: written at the first logged period, then at each change. `log_source` and `plan_name` are the one mapping between the two.
LOG_TOPICS = {"plant": "/plant/truth", "sensor": "/plant/sensors", "ctrl": "/ctrl/telemetry",
              "cmd": "/cmd", SAMPLE_GROUP: "/plant/sample_sensors"}
#: A sensor-set board's SAMPLE_SENSORS fields (``sample.<field>``, only its set's) and the
#: plant's winding temperature, one row a period, in their own topic: a board that gets today's
#: SAMPLE has neither and its log is what it always was.
SAMPLE_SENSORS_TOPIC = LOG_TOPICS[SAMPLE_GROUP]
_WINDING_FIELD = WINDING_TEMPERATURE_SIGNAL.partition(".")[2]
STEP_TOPIC_PREFIX = "/step/"
STEP_FIELD = "value"
_GROUP_FIELDS = {"plant": TRUTH_FIELDS, "sensor": SENSOR_FIELDS, "ctrl": TELEMETRY_FIELDS,
                 "cmd": COMMAND_FIELDS, SAMPLE_GROUP: ALL_SENSOR_FIELDS}
#: Topics whose messages are changes of a value held until the next (commands, step signals).
HELD_TOPICS = ("/cmd",)


def log_source(name: str) -> tuple[str, str] | None:
    """(topic, field) of the signal `name` (``group.field``) in a run log; None if not a
    signal name."""
    group, dot, field = name.partition(".")
    if not (dot and group and field):
        return None
    if name == WINDING_TEMPERATURE_SIGNAL:
        return SAMPLE_SENSORS_TOPIC, _WINDING_FIELD
    if field in _GROUP_FIELDS.get(group, ()):
        return LOG_TOPICS[group], field
    return STEP_TOPIC_PREFIX + name, STEP_FIELD


def plan_name(topic: str, field: str) -> str | None:
    """The signal name plans use for `field` of `topic` in a run log, None if it has none."""
    if topic == SAMPLE_SENSORS_TOPIC and field == _WINDING_FIELD:
        return WINDING_TEMPERATURE_SIGNAL
    for group, group_topic in LOG_TOPICS.items():
        if topic == group_topic:
            return f"{group}.{field}" if field in _GROUP_FIELDS[group] else None
    if topic.startswith(STEP_TOPIC_PREFIX) and field == STEP_FIELD:
        return topic[len(STEP_TOPIC_PREFIX):]
    return None


def is_held(topic: str) -> bool:
    """True if the topic's messages are changes of values held until the next."""
    return topic in HELD_TOPICS or topic.startswith(STEP_TOPIC_PREFIX)


#: The C codec's row writers (one call a period's rows, one a TELEMETRY), or None.
_STAGE_PERIOD = ccodec.stage_period if ccodec.AVAILABLE else None
_STAGE_TELEMETRY = ccodec.stage_telemetry if ccodec.AVAILABLE else None


#: A TELEMETRY as its row: the period, then TELEMETRY_FIELDS.
telemetry_row = attrgetter("period", *TELEMETRY_FIELDS)

#: Rows of the stage that TELEMETRY may fill before a batch is sealed early (a board sends at
#: most one a period; twice the batch is room for one that sends more now and then).
TELEMETRY_STAGE_ROWS = 2 * LOG_BATCH_PERIODS
_TRUTH_WIDTH = len(TRUTH_FIELDS)


def _log_times(periods, period_s: float) -> np.ndarray:
    """k -> round(k T 1e9) ns, rounding half to even like Python's round()."""
    return np.rint(np.asarray(periods, dtype=np.float64) * period_s * 1e9).astype(np.uint64)


def _joined(blocks: list[np.ndarray], pending: np.ndarray, empty_shape: tuple,
            dtype=np.float64) -> np.ndarray:
    """The sealed blocks and this batch's rows as one array."""
    parts = blocks + [pending] if len(pending) else blocks
    if not parts:
        return np.empty(empty_shape, dtype=dtype)
    return parts[0].copy() if len(parts) == 1 else np.concatenate(parts)


def unit_of(field: str) -> str:
    """Unit of a logged field, from the naming convention (units in names)."""
    for suffix, unit in (("_rad_s", "rad/s"), ("_rpm", "rpm"), ("_rad", "rad"), ("_wb", "Wb"),
                         ("_nm", "Nm"), ("_s", "s"), ("_v", "V"), ("_a", "A")):
        if field.endswith(suffix):
            return unit
    if field.startswith(("i_", "adc_i")):
        return "A" if field.startswith("i_") else ""
    if field.startswith("psi_"):
        return "Wb"
    if field.startswith(("u_", "v_")):
        return "V"
    return ""


class Recorder:
    """Per-period rows, optionally mirrored to an McapLog.

    A period's rows go straight into this batch's float64 stage (truth, sensors with the
    period first, telemetry with the period first), preallocated once: one C call from
    Python (protocol.ccodec.stage_period, stage_telemetry), or written by the C period loop itself
    (protocol.ccodec.exchange_periods, through `batch_stage`). Every LOG_BATCH_PERIODS periods
    the stage is sealed: copied into blocks the run keeps for its checks and, with a log, sent
    to it in one batch per channel. The run keeps blocks, not objects: 336 bytes a period
    instead of about 1.4 kB of tuples, floats and messages, which the garbage collector would
    otherwise walk again and again and the run's end would free one by one.
    """

    def __init__(self, period_s: float):
        self.period_s = period_s
        # This batch's stage: sensors (period + SENSOR_FIELDS), truth (TRUTH_FIELDS) and
        # telemetry (period + TELEMETRY_FIELDS) rows, and how many of each are filled. A
        # batch seals at LOG_BATCH_PERIODS periods, or early if TELEMETRY floods it.
        self._sensor_stage = np.empty((LOG_BATCH_PERIODS, 1 + len(SENSOR_FIELDS)))
        self._truth_stage = np.empty((LOG_BATCH_PERIODS, len(TRUTH_FIELDS)))
        self._telemetry_stage = np.empty((TELEMETRY_STAGE_ROWS, 1 + len(TELEMETRY_FIELDS)))
        self._fill = np.zeros(2, dtype=np.int64)         # periods, telemetry rows
        self._stage = (self._sensor_stage, self._truth_stage, self._telemetry_stage, self._fill)
        # sealed batches: periods (int64), truth, sensors (period + SENSOR_FIELDS) and
        # telemetry (period + TELEMETRY_FIELDS) rows, float64
        self._period_blocks: list[np.ndarray] = []
        self._truth_blocks: list[np.ndarray] = []
        self._sensor_blocks: list[np.ndarray] = []
        self._telemetry_blocks: list[np.ndarray] = []
        self.command_rows: list[tuple] = []
        # Step signals that change now and then (board fault code, injected faults):
        # name -> [(period, value)], held until the next change.
        self.step_rows: dict[str, list[tuple[int, float]]] = {name: [] for name in STEP_SIGNALS}
        # step signals in the log: rows of step_rows written (or passed), and the value held
        self._step_logged: dict[str, int] = {}
        self._step_held: dict[str, float] = {}
        self._last_logged_period: int | None = None
        self._log = None
        self._truth_ch = self._sensor_ch = self._telemetry_ch = None
        self._frames_ch = None
        # hil.live.LiveStream (or anything with period(), telemetry_row() and `every`): every
        # `every`-th row goes to the live viewers too
        self.live = None
        # a sensor-set board's rows (record_sample_sensors): period + fields (+ temperature)
        self.sample_fields: tuple[str, ...] = ()
        self._sample_stage: np.ndarray | None = None
        self._sample_fill = 0
        self._sample_blocks: list[np.ndarray] = []
        self._sample_ch = None

    def attach_log(self, log) -> None:
        """Logs the periods from now on (what came before stays in memory only)."""
        self.seal()
        self._log = log
        self._truth_ch = log.add_fixed_channel(
            "/plant/truth", "hil.PlantTruth", [(f, "double" if f == "t_s" else "float")
                                               for f in TRUTH_FIELDS])
        self._sensor_ch = log.add_fixed_channel(
            "/plant/sensors", "hil.SensorSample",
            [("period", "fixed32")] + [(f, "fixed32") for f in SENSOR_FIELDS])
        self._telemetry_ch = log.add_fixed_channel(
            "/ctrl/telemetry", "hil.Telemetry",
            [("period", "fixed32")] + [(f, "fixed32" if i < 4 else "float")
                                       for i, f in enumerate(TELEMETRY_FIELDS)])
        log.before_flush(self.seal)
        if self._sample_stage is not None:
            self._add_sample_channel()

    def record_sample_sensors(self, fields: tuple[str, ...], temperature: bool) -> None:
        """From now on every period also has a row of `fields` (a sensor-set board's
        SAMPLE_SENSORS fields, ``sample.<field>``) and, with `temperature`, the plant's winding
        temperature (plant.winding_temperature_degc): `sample_row` writes it."""
        self.seal()
        self.sample_fields = tuple(fields) + ((_WINDING_FIELD,) if temperature else ())
        self._sample_stage = np.empty((LOG_BATCH_PERIODS, 1 + len(self.sample_fields)))
        self._sample_fill = 0
        if self._log is not None:
            self._add_sample_channel()

    def _add_sample_channel(self) -> None:
        self._sample_ch = self._log.add_fixed_channel(
            SAMPLE_SENSORS_TOPIC, "hil.SampleSensors",
            [("period", "fixed32")] + [(f, "float" if f == _WINDING_FIELD else "fixed32")
                                       for f in self.sample_fields])

    def sample_row(self, k: int, values: tuple) -> None:
        """Period k's row of the fields record_sample_sensors named, in that order."""
        n = self._sample_fill
        stage = self._sample_stage
        stage[n, 0] = k
        stage[n, 1:] = values
        self._sample_fill = n + 1
        if n + 1 >= LOG_BATCH_PERIODS:
            self._seal_samples()

    def _seal_samples(self) -> None:
        n = self._sample_fill
        if not n:
            return
        self._sample_fill = 0
        rows = self._sample_stage[:n].copy()
        self._sample_blocks.append(rows)
        if self._sample_ch is not None:
            self._sample_ch.write_many(_log_times(rows[:, 0], self.period_s), rows)

    def period(self, k: int, truth: tuple, sample) -> None:
        if _STAGE_PERIOD is None or type(truth) is not tuple:
            self._period_numpy(k, truth, sample)
        else:
            try:
                _STAGE_PERIOD(self._stage, self.seal, k, truth, sample)
            except TypeError:               # a value that is not a plain number
                self._period_numpy(k, truth, sample)
        live = self.live
        if live is not None and k % live.every == 0:
            live.period(k, truth, sample)

    def _period_numpy(self, k: int, truth, sample) -> None:
        """period()'s rows without the C codec (or for values it does not take)."""
        if len(truth) != _TRUTH_WIDTH:
            raise ValueError(f"recorder: rows of {len(truth)} values where the log's channel has "
                             f"{_TRUTH_WIDTH}")
        fill = self._fill
        n = int(fill[0])
        self._truth_stage[n] = truth
        self._sensor_stage[n] = (k, sample.adc_i1, sample.adc_i2, sample.adc_vdc, sample.encoder,
                                 sample.status)
        fill[0] = n + 1
        if n + 1 >= LOG_BATCH_PERIODS:
            self.seal()

    def telemetry(self, msg) -> None:
        if _STAGE_TELEMETRY is not None and type(msg) is Telemetry:
            _STAGE_TELEMETRY(self._stage, self.seal, msg)
        else:
            fill = self._fill
            n = int(fill[1])
            self._telemetry_stage[n] = telemetry_row(msg)
            fill[1] = n + 1
            if n + 1 >= TELEMETRY_STAGE_ROWS:
                self.seal()
        live = self.live
        if live is not None and msg.period % live.every == 0:
            live.telemetry_row(telemetry_row(msg))

    def batch_stage(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """This batch's stage (sensors, truth, telemetry rows, and the int64 fill counts) for
        a period loop in C (protocol.ccodec.exchange_periods) that writes into it what period()
        and telemetry() would and calls seal() when a part fills; it leaves to period() and
        telemetry() the rows a live viewer takes (every `live.every`-th). seal() empties the
        stage in place (the fill counts to 0), never replacing its arrays."""
        return self._stage

    def seal(self) -> None:
        """This batch's rows become float64 blocks and, with a log, go to it (every
        LOG_BATCH_PERIODS periods, when TELEMETRY fills its stage, and before the log flushes
        or closes)."""
        log = self._log
        fill = self._fill
        n, m = int(fill[0]), int(fill[1])
        fill[0] = fill[1] = 0
        if self._sample_fill:
            self._seal_samples()
        if n:
            sensors = self._sensor_stage[:n].copy()
            truth = self._truth_stage[:n].copy()
            periods = sensors[:, 0].astype(np.int64)
            self._period_blocks.append(periods)
            self._truth_blocks.append(truth)
            self._sensor_blocks.append(sensors)
            if log is not None:
                t_ns = _log_times(periods, self.period_s)
                self._truth_ch.write_many(t_ns, truth)
                self._sensor_ch.write_many(t_ns, sensors)
                self._log_steps(int(periods[0]), int(periods[-1]))
                self._last_logged_period = int(periods[-1])
        elif log is not None and self._last_logged_period is not None:
            # a change that came after the last period's rows (a STATUS at the run's end)
            self._log_steps(self._last_logged_period, self._last_logged_period)
        if m:
            rows = self._telemetry_stage[:m].copy()
            self._telemetry_blocks.append(rows)
            if log is not None:
                self._telemetry_ch.write_many(_log_times(rows[:, 0], self.period_s), rows)

    @property
    def period_count(self) -> int:
        """Periods recorded (since the last clear())."""
        return sum(map(len, self._period_blocks)) + int(self._fill[0])

    @property
    def periods(self) -> np.ndarray:
        """Every recorded period's number, int64, in order (made anew at each call)."""
        pending = self._sensor_stage[:int(self._fill[0]), 0].astype(np.int64)
        return _joined(self._period_blocks, pending, (0,), np.int64)

    @property
    def truth_rows(self) -> np.ndarray:
        """(periods, TRUTH_FIELDS) float64 rows (made anew at each call; `latest_row` reads
        the newest at no cost)."""
        return _joined(self._truth_blocks, self._truth_stage[:int(self._fill[0])],
                       (0, _TRUTH_WIDTH))

    @property
    def sensor_rows(self) -> np.ndarray:
        """(periods, SENSOR_FIELDS) float64 rows (made anew at each call)."""
        return _joined([b[:, 1:] for b in self._sensor_blocks],
                       self._sensor_stage[:int(self._fill[0]), 1:], (0, len(SENSOR_FIELDS)))

    @property
    def telemetry_rows(self) -> np.ndarray:
        """(TELEMETRY messages, period + TELEMETRY_FIELDS) float64 rows in arrival order, made
        anew at each call (a run's worth: milliseconds; `latest` reads the newest value)."""
        return _joined(self._telemetry_blocks, self._telemetry_stage[:int(self._fill[1])],
                       (0, 1 + len(TELEMETRY_FIELDS)))

    def latest_row(self, group: str):
        """The newest truth, sensors or telemetry row (telemetry's starts with the period),
        None before the first: for readers that poll while a run goes on (a copy of one row:
        the stage is written again)."""
        n, m = int(self._fill[0]), int(self._fill[1])
        if group == "telemetry":
            if m:
                return self._telemetry_stage[m - 1].copy()
            blocks = self._telemetry_blocks
        elif group == "truth":
            if n:
                return self._truth_stage[n - 1].copy()
            blocks = self._truth_blocks
        else:
            if n:
                return self._sensor_stage[n - 1, 1:].copy()
            return self._sensor_blocks[-1][-1, 1:] if self._sensor_blocks else None
        return blocks[-1][-1] if blocks else None

    def latest_sample(self, field: str) -> float:
        """The newest value of a sample_row field (``hall``, ``winding_temperature_degc``),
        NaN before the first or when this run does not record it."""
        if field not in self.sample_fields:
            return math.nan
        i = self.sample_fields.index(field) + 1
        if self._sample_fill:
            return float(self._sample_stage[self._sample_fill - 1, i])
        return float(self._sample_blocks[-1][-1, i]) if self._sample_blocks else math.nan

    def latest(self, group: str, index: int) -> float:
        """Value `index` of the newest truth, sensors or telemetry row (the row's order:
        telemetry's starts with the period), NaN before the first."""
        row = self.latest_row(group)
        return math.nan if row is None else float(row[index])

    def clear(self) -> None:
        """Forgets the rows kept in memory (a long run that checks as it goes), after writing
        to the log the ones it does not have yet."""
        self.seal()
        for blocks in (self._period_blocks, self._truth_blocks, self._sensor_blocks,
                       self._telemetry_blocks, self._sample_blocks):
            blocks.clear()

    def command(self, k: int, row: tuple) -> None:
        self.command_rows.append((k, *row))
        if self._log is not None:
            self._log.write_json("/cmd", round(k * self.period_s * 1e9),
                                 dict(zip(COMMAND_FIELDS, row), period=k))

    def step_value(self, name: str, k: int, value: float) -> None:
        """A step signal (``group.field``) takes ``value`` from period k on."""
        self.step_rows.setdefault(name, []).append((k, float(value)))

    def _log_steps(self, first: int, last: int) -> None:
        """The step signals' changes up to period `last` into the log, one topic each, in
        time order: a signal's first message is its value at period `first` (0 before any
        change), later ones each change (sealed with the batch of periods first..last)."""
        for name, rows in self.step_rows.items():
            i = self._step_logged.get(name)
            if i is None:               # not in the log yet: its value at `first`
                value, i = 0.0, 0
                while i < len(rows) and rows[i][0] <= first:
                    value, i = rows[i][1], i + 1
                self._write_step(name, first, value)
            held = self._step_held[name]
            while i < len(rows) and rows[i][0] <= last:
                k, value = rows[i]
                if value != held:
                    self._write_step(name, k, value)
                    held = value
                i += 1
            self._step_logged[name] = i

    def _write_step(self, name: str, k: int, value: float) -> None:
        self._step_held[name] = value
        self._log.write_json(STEP_TOPIC_PREFIX + name, round(k * self.period_s * 1e9),
                             {STEP_FIELD: value, "period": k})

    def frames(self, k: int, capture: dict[str, tuple[bytes, int]]) -> None:
        """Raw frames of the last batch of periods, one log message per direction."""
        if self._log is None:
            return
        if self._frames_ch is None:
            self._frames_ch = {
                "out": self._log.add_bytes_channel("/link/frames_out", "hil.RawFrames"),
                "in": self._log.add_bytes_channel("/link/frames_in", "hil.RawFrames")}
        t_ns = round(k * self.period_s * 1e9)
        for direction, (data, count) in capture.items():
            if count:
                self._frames_ch[direction].write(t_ns, data, count)

    # ---------------------------------------------------------------- export
    def arrays(self) -> dict[str, tuple[np.ndarray, np.ndarray, str]]:
        """name -> (t_s, values, unit) for every recorded signal."""
        out: dict[str, tuple[np.ndarray, np.ndarray, str]] = {}
        k = self.periods
        if len(k):
            t = k * self.period_s
            truth = self.truth_rows
            for i, name in enumerate(TRUTH_FIELDS):
                out[f"plant.{name}"] = (t, truth[:, i], unit_of(name))
            sensors = self.sensor_rows
            for i, name in enumerate(SENSOR_FIELDS):
                out[f"sensor.{name}"] = (t, sensors[:, i], "")
            # Commands are step signals: hold each value until the next command.
            if self.command_rows:
                cmd = np.asarray(self.command_rows, dtype=np.float64)
                idx = np.searchsorted(cmd[:, 0], k, side="right") - 1
                valid = idx >= 0
                for i, name in enumerate(COMMAND_FIELDS):
                    values = np.full(len(k), np.nan)
                    values[valid] = cmd[idx[valid], i + 1]
                    out[f"cmd.{name}"] = (t, values, unit_of(name))
            # Step signals on the period grid: 0 before their first change.
            for name, rows in self.step_rows.items():
                values = np.zeros(len(k))
                if rows:
                    at = np.asarray([r[0] for r in rows])
                    idx = np.searchsorted(at, k, side="right") - 1
                    values[idx >= 0] = np.asarray([r[1] for r in rows])[idx[idx >= 0]]
                out[name] = (t, values, "")
        if self.sample_fields:
            rows = _joined(self._sample_blocks, self._sample_stage[:self._sample_fill],
                           (0, 1 + len(self.sample_fields)))
            t_sample = rows[:, 0] * self.period_s
            for i, name in enumerate(self.sample_fields):
                signal = (WINDING_TEMPERATURE_SIGNAL if name == _WINDING_FIELD
                          else f"{SAMPLE_GROUP}.{name}")
                out[signal] = (t_sample, rows[:, i + 1], "degC" if name == _WINDING_FIELD else "")
        tel = self.telemetry_rows
        if len(tel):
            t_tel = tel[:, 0] * self.period_s
            for i, name in enumerate(TELEMETRY_FIELDS):
                out[f"ctrl.{name}"] = (t_tel, tel[:, i + 1], unit_of(name))
        return out
