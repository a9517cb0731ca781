"""The records after a chunk (its MessageIndexes and its ChunkIndex) come from one C call
(protocol.ccodec.chunk_tail) where Python built them a channel at a time: checked against
records laid out by hand from the MCAP spec's field tables, against the Python path for whole
files, and for the inputs it refuses."""
from __future__ import annotations

import struct
from array import array

import numpy as np
import pytest
from mcap.reader import make_reader

from hil.logs import mcap_writer
from hil.logs.mcap_writer import McapLog
from protocol import ccodec

pytestmark = pytest.mark.skipif(not ccodec.AVAILABLE or ccodec.chunk_tail is None,
                                reason=ccodec.UNAVAILABLE_REASON or "an old _hilcodec build")


def _by_hand(ids, pairs, chunk_start, chunk_length, start, end, compression, compressed, raw):
    """The spec's layout, field by field: MessageIndex (0x07) = channel_id uint16, records
    (uint32 byte length, then (log_time uint64, offset uint64) pairs); ChunkIndex (0x08) =
    message_start_time, message_end_time, chunk_start_offset, chunk_length (uint64 each),
    message_index_offsets (uint32 byte length, then (uint16, uint64) entries),
    message_index_length uint64, compression (uint32 length + bytes), compressed_size and
    uncompressed_size (uint64). Every record: opcode uint8, body length uint64."""
    indexes = b""
    entries = b""
    pos = chunk_start + chunk_length
    for cid, p in zip(ids, pairs):
        body = cid.to_bytes(2, "little") + (16 * len(p)).to_bytes(4, "little")
        body += b"".join(t.to_bytes(8, "little") + o.to_bytes(8, "little") for t, o in p)
        record = b"\x07" + len(body).to_bytes(8, "little") + body
        entries += cid.to_bytes(2, "little") + pos.to_bytes(8, "little")
        pos += len(record)
        indexes += record
    name = compression.encode()
    body = b"".join(v.to_bytes(8, "little") for v in (start, end, chunk_start, chunk_length))
    body += len(entries).to_bytes(4, "little") + entries
    body += len(indexes).to_bytes(8, "little")
    body += len(name).to_bytes(4, "little") + name
    body += compressed.to_bytes(8, "little") + raw.to_bytes(8, "little")
    return indexes, b"\x08" + len(body).to_bytes(8, "little") + body


def test_records_match_the_spec_layout_built_by_hand():
    rng = np.random.default_rng(11)
    for trial in range(150):
        n = int(rng.integers(0, 6))
        ids = [int(v) for v in rng.choice(65536, size=n, replace=False)]
        pairs = [[(int(rng.integers(0, 2 ** 63)), int(rng.integers(0, 2 ** 32)))
                  for _ in range(int(rng.integers(1, 30)))] for _ in ids]
        numbers = [int(v) for v in rng.integers(0, 2 ** 62, size=6)]
        compression = ("lz4", "zstd", "")[trial % 3]
        args = (numbers[0], numbers[1], numbers[2], numbers[3], compression, numbers[4], numbers[5])
        got = ccodec.chunk_tail(ids, [array("Q", [v for pair in p for v in pair]) for p in pairs],
                                *args)
        assert got == _by_hand(ids, pairs, *args)


def test_refuses_what_it_cannot_lay_out():
    one = array("Q", [5, 0])
    tail = (0, 10, 5, 5, "lz4", 3, 4)
    with pytest.raises(ValueError, match="2 channel ids for 1 indexes"):
        ccodec.chunk_tail([1, 2], [one], *tail)
    with pytest.raises(ValueError, match="index 1 holds 24 bytes"):
        ccodec.chunk_tail([1, 2], [one, array("Q", [1, 2, 3])], *tail)
    for bad in (-1, 65536, 2 ** 70, "1"):
        with pytest.raises(ValueError, match="channel id 0 is not a uint16"):
            ccodec.chunk_tail([bad], [one], *tail)
    with pytest.raises(ValueError, match="argument 4 is not a uint64"):
        ccodec.chunk_tail([1], [one], 0, -10, 5, 5, "lz4", 3, 4)
    with pytest.raises(TypeError, match="9 arguments"):
        ccodec.chunk_tail([1], [one], 0)


def _write(path, c_tail: bool, monkeypatch) -> bytes:
    """Three channels, one of them silent in some chunks, over many small chunks."""
    monkeypatch.setattr(mcap_writer, "_CHUNK_TAIL", ccodec.chunk_tail if c_tail else None)
    log = McapLog(path, chunk_size=1024)
    a = log.add_fixed_channel("/a", "hil.A", [("x", "double"), ("k", "fixed32")])
    frames = log.add_bytes_channel("/frames", "hil.Frames")
    for i in range(300):
        t = 1_000_000 + 50_000 * i
        a.write_many(np.array([t, t + 1], dtype=np.uint64), np.array([[i * 0.5, i], [i * 0.25, i]]))
        if i % 7 == 0:
            frames.write(t, bytes(range(i % 50)), i % 50)
        if i % 40 == 0:
            log.write_json("/events", t, {"i": i})
    log.close()
    monkeypatch.undo()
    return path.read_bytes()


def test_a_log_is_byte_identical_to_the_python_path(tmp_path, monkeypatch):
    c = _write(tmp_path / "c.mcap", True, monkeypatch)
    py = _write(tmp_path / "py.mcap", False, monkeypatch)
    assert c == py
    # and the mcap package finds every message through the indexes (its seeking reader reads
    # the ChunkIndexes and MessageIndexes to locate them)
    with open(tmp_path / "c.mcap", "rb") as f:
        reader = make_reader(f)
        counts = {}
        for _, channel, message in reader.iter_messages():
            counts[channel.topic] = counts.get(channel.topic, 0) + 1
        summary = reader.get_summary()
    assert counts == {"/a": 600, "/frames": 43, "/events": 8}
    assert len(summary.chunk_indexes) > 20
    assert sum(len(ci.message_index_offsets) for ci in summary.chunk_indexes) > 40
    first = summary.chunk_indexes[0]
    with open(tmp_path / "c.mcap", "rb") as f:       # the first MessageIndex sits where it says
        f.seek(min(first.message_index_offsets.values()))
        opcode, = struct.unpack("<B", f.read(1))
    assert opcode == 0x07
