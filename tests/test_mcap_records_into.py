"""FixedChannel.write_many packs its records in one C call (protocol.ccodec.records_into) where
it used numpy column by column: the same bytes in the file for every field type and the edge
values of each, and for values that do not fit, the numpy path's error (naming the value and the
field) with nothing written."""
from __future__ import annotations

import math

import numpy as np
import pytest

from hil.logs import mcap_writer
from hil.logs.mcap_writer import McapLog
from hil.logs.reader import read_log
from protocol import ccodec

pytestmark = pytest.mark.skipif(not ccodec.AVAILABLE or ccodec.records_into is None,
                                reason=ccodec.UNAVAILABLE_REASON or "an old _hilcodec build")

FIELDS = [("t", "double"), ("x", "float"), ("k", "fixed32"), ("s", "sfixed32"), ("big", "fixed64"),
          ("neg", "sfixed64")]


def _rows() -> tuple[np.ndarray, np.ndarray]:
    f32_max = float(np.finfo(np.float32).max)
    rows = np.array([
        [0.0, 0.0, 0, 0, 0, 0],
        [-0.0, -0.0, 1, -1, 1, -1],
        [1e-310, 1e-45, 4294967295, 2147483647, 2.0 ** 63, 2.0 ** 62],
        [math.pi, math.pi, 123456789, -2147483648, 2.0 ** 64 - 2048, -(2.0 ** 63)],
        [math.inf, math.inf, 7, 7, 7, 7],
        [-math.inf, -math.inf, 8, -8, 8, -8],
        [math.nan, math.nan, 9, 9, 9, 9],
        [1e300, f32_max, 10, 10, 10, 10],
        [-1e300, -f32_max, 11, -11, 11, -11],
        [2.5e-8, 0.1, 12, 12, 12, 12],
    ], dtype=np.float64)
    times = np.arange(len(rows), dtype=np.uint64) * 50_000 + 7
    return times, rows


def _write(path, c_pack: bool, monkeypatch, chunk_size=4096, repeat=40):
    monkeypatch.setattr(mcap_writer, "_RECORDS_INTO", ccodec.records_into if c_pack else None)
    times, rows = _rows()
    log = McapLog(path, chunk_size=chunk_size)
    ch = log.add_fixed_channel("/edge", "hil.Edge", FIELDS)
    for i in range(repeat):                          # spans several chunks
        ch.write_many(times + np.uint64(i * 1_000_000), rows)
    log.close()
    monkeypatch.undo()
    return path.read_bytes()


def test_the_c_packer_writes_the_numpy_path_bytes(tmp_path, monkeypatch):
    c = _write(tmp_path / "c.mcap", True, monkeypatch)
    py = _write(tmp_path / "py.mcap", False, monkeypatch)
    assert c == py
    back = read_log(tmp_path / "c.mcap")["/edge"].fields
    assert len(back["k"]) == 400 and list(back["k"][:4]) == [0, 1, 4294967295, 123456789]
    assert list(back["neg"][:4]) == [0, -1, 2 ** 62, -(2 ** 63)]


@pytest.mark.parametrize("field, value, message", [
    (2, -1.0, "'k' = -1.0: outside 0..4294967295"),
    (2, 2.5, "'k' = 2.5: a whole number is expected"),
    (3, 2147483648.0, "'s' = 2147483648.0: outside"),
    (5, math.nan, "'neg' = nan: a whole number is expected"),
    (1, 1e39, "a value does not fit its field type"),
])
def test_a_value_that_does_not_fit_gets_the_numpy_paths_error(tmp_path, monkeypatch, field, value, message):
    times, rows = _rows()
    rows[4, field] = value
    log = McapLog(tmp_path / "bad.mcap")
    ch = log.add_fixed_channel("/edge", "hil.Edge", FIELDS)
    with pytest.raises(ValueError, match=message):
        ch.write_many(times, rows)
    assert log._open.fill == 0                      # nothing of the batch written
    log.close()


def test_records_into_checks_before_writing():
    out = bytearray(b"\xaa" * 200)
    template = bytes(range(40))
    with pytest.raises(ValueError, match="row 1, field 0 does not fit"):
        ccodec.records_into(out, 0, template, b"I", (33,), np.array([1, 2], np.uint64),
                            np.array([1.0, -3.0]))
    assert out == bytearray(b"\xaa" * 200)
    assert ccodec.records_into(out, 10, template, b"I", (33,), np.array([1, 2], np.uint64),
                               np.array([1.0, 3.0])) == 2
    assert out[10:10 + 15] == template[:15] and out[10 + 33:10 + 37] == (1).to_bytes(4, "little")
    assert out[50 + 15:50 + 23] == (2).to_bytes(8, "little") and out[:10] == b"\xaa" * 10
    with pytest.raises(ValueError, match="do not go together"):
        ccodec.records_into(bytearray(60), 0, template, b"I", (33,), np.array([1, 2], np.uint64),
                            np.array([1.0, 3.0]))
    with pytest.raises(ValueError, match="does not fit a 40-byte record"):
        ccodec.records_into(out, 0, template, b"d", (33,), np.array([1], np.uint64), np.array([1.0]))


@pytest.mark.parametrize("code, fits, fails", [
    ("I", [0.0, 4294967295.0], [-1.0, 4294967296.0, 0.5, math.inf, math.nan]),
    ("i", [-2147483648.0, 2147483647.0], [-2147483649.0, 2147483648.0, -0.5, -math.inf, math.nan]),
    ("Q", [0.0, 2.0 ** 63, 2.0 ** 64 - 2048], [-1.0, 2.0 ** 64, 1.5, math.inf, math.nan]),
    ("q", [-(2.0 ** 63), 2.0 ** 63 - 1024], [2.0 ** 63, -(2.0 ** 63) - 2048, 0.25, -math.inf, math.nan]),
    ("f", [3.4028234663852886e38, math.inf, math.nan], [3.5e38, -1e39]),
])
def test_records_into_takes_each_types_range_to_its_ends(code, fits, fails):
    """The boundaries of each integer type, both sides (the check is a range test, then a
    whole-number test through a conversion that is defined only inside the range)."""
    template = bytes(40)
    for value in fits:
        out = bytearray(40)
        assert ccodec.records_into(out, 0, template, code.encode(), (31,),
                                   np.array([5], np.uint64), np.array([value])) == 1
    for value in fails:
        with pytest.raises(ValueError, match="row 0, field 0 does not fit"):
            ccodec.records_into(bytearray(40), 0, template, code.encode(), (31,),
                                np.array([5], np.uint64), np.array([value]))
