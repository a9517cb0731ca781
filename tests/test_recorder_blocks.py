"""The recorder seals its rows into float64 blocks every LOG_BATCH_PERIODS periods: what it
hands back (rows, arrays, the newest value, the log) is what it was given, across seals,
clear() and a log attached mid-run; and a long run keeps blocks, not Python objects."""
from __future__ import annotations

import math
import tracemalloc
from types import SimpleNamespace

import numpy as np
import pytest

from hil.logs.mcap_writer import McapLog
from hil.logs.reader import read_log
from hil.logs.recorder import LOG_BATCH_PERIODS, SENSOR_FIELDS, TELEMETRY_FIELDS, Recorder
from plant_rt import TRUTH_FIELDS
from protocol.messages import Telemetry

T = 50e-6


def _truth(k: int) -> tuple:
    return tuple(k * T if i == 0 else math.sin(k + i) * 10.0 ** (i % 5) for i in range(len(TRUTH_FIELDS)))


def _sample(k: int):
    return SimpleNamespace(adc_i1=k % 4096, adc_i2=(3 * k) % 4096, adc_vdc=3000 + k % 7,
                           encoder=(k * 13) % 65536, status=k % 2)


def _telemetry(k: int) -> Telemetry:
    return Telemetry(k, k % 6, 2, 1, 0x21, *[0.25 * k + i for i in range(12)])


def _feed(rec: Recorder, ks) -> None:
    for k in ks:
        rec.period(k, _truth(k), _sample(k))
        rec.telemetry(_telemetry(k))


def _want(ks):
    truth = np.array([_truth(k) for k in ks], dtype=np.float64)
    sensors = np.array([[getattr(_sample(k), f) for f in SENSOR_FIELDS] for k in ks], dtype=np.float64)
    telemetry = np.array([[getattr(_telemetry(k), f) for f in ("period",) + TELEMETRY_FIELDS]
                          for k in ks], dtype=np.float64)
    return truth, sensors, telemetry


def test_rows_across_seals_are_the_rows_given():
    n = 3 * LOG_BATCH_PERIODS + 17                  # three sealed blocks and a partial batch
    rec = Recorder(T)
    _feed(rec, range(n))
    truth, sensors, telemetry = _want(range(n))
    assert rec.period_count == n and rec.periods.tolist() == list(range(n))
    assert np.array_equal(rec.truth_rows, truth)
    assert np.array_equal(rec.sensor_rows, sensors)
    assert np.array_equal(rec.telemetry_rows, telemetry)
    arrays = rec.arrays()
    assert np.array_equal(arrays["plant.speed_rpm"][1], truth[:, TRUTH_FIELDS.index("speed_rpm")])
    assert np.array_equal(arrays["plant.speed_rpm"][0], np.arange(n) * T)
    assert np.array_equal(arrays["sensor.encoder"][1], sensors[:, SENSOR_FIELDS.index("encoder")])
    assert np.array_equal(arrays["ctrl.gates"][1], telemetry[:, 1 + TELEMETRY_FIELDS.index("gates")])
    # the newest value, from the open batch and right after a seal
    assert rec.latest("truth", 3) == truth[-1, 3] and rec.latest("sensors", 3) == sensors[-1, 3]
    _feed(rec, range(n, 4 * LOG_BATCH_PERIODS))
    truth, sensors, telemetry = _want(range(4 * LOG_BATCH_PERIODS))
    assert rec.period_count == 4 * LOG_BATCH_PERIODS
    for group, rows in (("truth", truth), ("sensors", sensors), ("telemetry", telemetry)):
        assert np.array_equal(np.asarray(rec.latest_row(group), dtype=np.float64), rows[-1]), group
    assert np.array_equal(rec.truth_rows, truth)


def test_clear_keeps_the_log_whole_and_a_log_attached_late_starts_there(tmp_path):
    rec = Recorder(T)
    _feed(rec, range(100))                          # before the log: memory only
    log = McapLog(tmp_path / "run.mcap")
    rec.attach_log(log)
    _feed(rec, range(100, 700))
    rec.clear()
    assert rec.period_count == 0 and len(rec.truth_rows) == 0 and math.isnan(rec.latest("truth", 0))
    _feed(rec, range(700, 1000))
    assert rec.periods.tolist() == list(range(700, 1000))
    log.close()
    data = read_log(tmp_path / "run.mcap")
    truth, sensors, telemetry = _want(range(100, 1000))
    assert np.array_equal(data["/plant/sensors"]["period"], np.arange(100, 1000))
    assert np.array_equal(data["/plant/sensors"]["encoder"], sensors[:, SENSOR_FIELDS.index("encoder")])
    speed = TRUTH_FIELDS.index("speed_rpm")          # float on the channel (t_s is the double)
    assert np.array_equal(data["/plant/truth"]["speed_rpm"], truth[:, speed].astype(np.float32))
    assert np.array_equal(data["/ctrl/telemetry"]["period"], np.arange(100, 1000))


def test_a_long_run_keeps_blocks_not_objects():
    """Design bound: a sealed period is 8 bytes x (1 + 19 truth + 6 sensor + 17 telemetry
    values) = 344 bytes, plus at most one open batch of Python objects (about 1.4 kB a period
    as tuples, floats and messages, which every period kept before the blocks)."""
    rec = Recorder(T)
    _feed(rec, range(LOG_BATCH_PERIODS))
    n = 40 * LOG_BATCH_PERIODS
    tracemalloc.start()
    try:
        before = tracemalloc.get_traced_memory()[0]
        # each period's objects made anew, as a session's plant and decoder make them
        _feed(rec, range(LOG_BATCH_PERIODS, LOG_BATCH_PERIODS + n))
        grown = tracemalloc.get_traced_memory()[0] - before
    finally:
        tracemalloc.stop()
    sealed = 8 * (1 + len(TRUTH_FIELDS) + 1 + len(SENSOR_FIELDS) + 1 + len(TELEMETRY_FIELDS))
    open_batch = LOG_BATCH_PERIODS * 1500
    assert grown < n * sealed * 1.2 + open_batch, (grown / n, sealed)


def test_the_c_row_writers_and_the_numpy_path_keep_the_same_rows(monkeypatch):
    """Recorder.period/telemetry through protocol.ccodec.stage_period/stage_telemetry and through
    numpy: the same rows, for a SensorSample (a tuple), an object with the attributes, truth
    values that are numpy scalars, and Fractions (not int or float: the C writer refuses them
    and the recorder hands the row to numpy)."""
    from fractions import Fraction
    from hil.logs import recorder as recorder_module
    from plant_rt.sensors import SensorSample

    def feed(rec):
        for k in range(3 * LOG_BATCH_PERIODS + 5):
            truth = _truth(k) if k % 3 else tuple(np.float64(v) for v in _truth(k))
            if k % 5 == 1:
                truth = tuple(Fraction(v) for v in _truth(k))
            s = _sample(k)
            sample = s if k % 2 else SensorSample(k, s.adc_i1, s.adc_i2, s.adc_vdc, s.encoder, s.status)
            rec.period(k, truth, sample)
            rec.telemetry(_telemetry(k))
        return rec.truth_rows, rec.sensor_rows, rec.telemetry_rows, rec.periods

    with_c = feed(Recorder(T))
    for name in ("_STAGE_PERIOD", "_STAGE_TELEMETRY"):
        monkeypatch.setattr(recorder_module, name, None)
    without = feed(Recorder(T))
    want = _want(range(3 * LOG_BATCH_PERIODS + 5))
    for a, b, w in zip(with_c, without, want):
        assert np.array_equal(a, b) and np.array_equal(a, w)
    assert np.array_equal(with_c[3], without[3])
    monkeypatch.undo()
    with pytest.raises(ValueError, match="rows of 3 values"):
        Recorder(T).period(0, (1.0, 2.0, 3.0), _sample(0))


def test_int_values_become_the_double_float_gives_them_on_both_paths(monkeypatch):
    """The C row writer converts an int without a float object in between: the same double as
    float(v), rounding included (2**53 + 1 and the like), for exact ints, bools and an int
    subclass, and the same rows as numpy's path; an int beyond a double's range is refused
    the same way on both (OverflowError)."""
    import enum

    from hil.logs import recorder as recorder_module

    class Code(enum.IntEnum):
        BIG = 2 ** 62 + 1

    awkward = [2 ** 53 + 1, -(2 ** 62) - 3, 10 ** 20 + 1, True, Code.BIG, 7, -1, 0]

    def truth(k):
        row = list(_truth(k))
        row[1:1 + len(awkward)] = awkward[k % 3:] + awkward[:k % 3]
        return tuple(row)

    def feed(rec):
        for k in range(LOG_BATCH_PERIODS + 3):
            s = _sample(k)
            rec.period(k, truth(k), SimpleNamespace(adc_i1=awkward[k % len(awkward)], adc_i2=s.adc_i2,
                                                    adc_vdc=s.adc_vdc, encoder=2 ** 53 + k, status=s.status))
        return rec.truth_rows, rec.sensor_rows

    with_c = feed(Recorder(T))
    monkeypatch.setattr(recorder_module, "_STAGE_PERIOD", None)
    without = feed(Recorder(T))
    monkeypatch.undo()
    for a, b in zip(with_c, without):
        assert np.array_equal(a, b)
    ks = range(LOG_BATCH_PERIODS + 3)
    assert [float(v) for v in with_c[0][:, 1]] == [float(truth(k)[1]) for k in ks]
    assert list(with_c[1][:, 0]) == [float(awkward[k % len(awkward)]) for k in ks]
    assert list(with_c[1][:, 3]) == [float(2 ** 53 + k) for k in ks]
    for writer_off in (False, True):
        if writer_off:
            monkeypatch.setattr(recorder_module, "_STAGE_PERIOD", None)
        with pytest.raises(OverflowError):
            Recorder(T).period(0, (10 ** 400,) + _truth(0)[1:], _sample(0))
    monkeypatch.undo()
