"""TELEMETRY rows written by the C codec (protocol.ccodec.stage_telemetry, what the recorder
and the C period loop write), as the recorder keeps and logs them: values in the SPEC's field
order, errors, and the same rows with and without the C codec."""
from __future__ import annotations

import numpy as np
import pytest

from hil.logs import recorder as recorder_module
from hil.logs.recorder import TELEMETRY_FIELDS, Recorder
from protocol import ccodec
from protocol.messages import Gates, Telemetry

needs_c = pytest.mark.skipif(not ccodec.AVAILABLE, reason=ccodec.UNAVAILABLE_REASON)


def _telemetry(k: int) -> Telemetry:
    return Telemetry(k, 3, 2, 1, 0x21, *[0.25 * k + i for i in range(12)])


def _stage(telemetry_rows: int):
    """A recorder stage (Recorder.batch_stage's layout) with room for `telemetry_rows`."""
    return (np.zeros((4, 6)), np.zeros((4, 19)), np.zeros((telemetry_rows, 17)),
            np.zeros(2, dtype=np.int64))


@needs_c
def test_stage_telemetry_writes_telemetry_rows_in_the_spec_field_order():
    """Expected rows written out by hand from the fields (SPEC order: period, sector,
    speed_source, state, gates, then the twelve floats), never from the function itself."""
    first = Telemetry(70000, 6, 1, 2, 0x2A, -1.5, 2.0, 3.25, 4.0, 5.0, -3.0, 3.0, 0.0928, 1.5, -2.0,
                      0.125, -0.125)
    second = Telemetry(70001, 1, 0, 2, 0x09, 0.0, -0.0, 1e-300, 1e300, -7.5, 0.5, -0.5, 0.1, 0.0, 0.0,
                       3.0, -3.0)
    stage = _stage(3)
    sealed = []
    for msg in (first, second):
        ccodec.stage_telemetry(stage, lambda: sealed.append(1), msg)
    got = stage[2]
    assert stage[3].tolist() == [0, 2] and not sealed and got[2].tolist() == [0.0] * 17
    assert got[0].tolist() == [70000.0, 6.0, 1.0, 2.0, 42.0, -1.5, 2.0, 3.25, 4.0, 5.0, -3.0, 3.0,
                               0.0928, 1.5, -2.0, 0.125, -0.125]
    assert got[1].tolist() == [70001.0, 1.0, 0.0, 2.0, 9.0, 0.0, -0.0, 1e-300, 1e300, -7.5, 0.5,
                               -0.5, 0.1, 0.0, 0.0, 3.0, -3.0]


@needs_c
def test_stage_telemetry_refuses_what_does_not_fit_or_is_not_a_number_by_name():
    msg = _telemetry(1)
    full = _stage(2)
    full[3][1] = 2
    with pytest.raises(ValueError, match="do not fit together"):
        ccodec.stage_telemetry(full, lambda: None, msg)
    with pytest.raises(TypeError, match="row 0, Telemetry 'sector' is str, not a number"):
        ccodec.stage_telemetry(_stage(2), lambda: None, Telemetry(1, "x", 0, 1, 0, *([0.5] * 12)))
    with pytest.raises(TypeError, match="not a Telemetry message"):
        ccodec.stage_telemetry(_stage(2), lambda: None, Gates(1, 0))
    with pytest.raises(TypeError, match="stage is"):
        ccodec.stage_telemetry((msg,), lambda: None, msg)
    with pytest.raises(BufferError):
        ccodec.stage_telemetry((bytes(48), bytes(152), bytes(272), np.zeros(2, np.int64)),
                               lambda: None, msg)


def test_recorder_telemetry_rows_are_the_same_with_and_without_the_c_codec(monkeypatch, tmp_path):
    """The rows in memory and in the log: from the C codec, from the Python attribute path,
    and written out here field by field, all equal."""
    from hil.logs.mcap_writer import McapLog
    from hil.logs.reader import read_log

    msgs = [_telemetry(k) for k in range(700)]            # more than two log batches
    want = np.array([[getattr(m, f) for f in ("period",) + TELEMETRY_FIELDS] for m in msgs])
    for c_codec in (True, False):
        for name in ("_STAGE_PERIOD", "_STAGE_TELEMETRY"):
            monkeypatch.setattr(recorder_module, name, getattr(recorder_module, name) if c_codec else None)
        rec = Recorder(50e-6)
        log = McapLog(tmp_path / f"{c_codec}.mcap")
        rec.attach_log(log)
        for k, m in enumerate(msgs):
            rec.period(k, (k * 50e-6,) + (0.0,) * 18, _Sample())
            rec.telemetry(m)
        assert np.array_equal(rec.telemetry_rows, want)
        assert rec.latest("telemetry", 1) == 3.0 and rec.latest("telemetry", 0) == 699.0
        log.close()
        monkeypatch.undo()
        logged = read_log(tmp_path / f"{c_codec}.mcap")["/ctrl/telemetry"]
        sector, speed = logged["sector"], logged["speed_feedback_rad_s"]
        assert len(sector) == 700 and np.all(sector == 3)
        assert np.array_equal(speed, want[:, 5].astype(np.float32))
    assert np.isnan(Recorder(50e-6).latest("telemetry", 0))


class _Sample:
    adc_i1, adc_i2, adc_vdc, encoder, status = 2048, 2048, 3000, 0, 0
