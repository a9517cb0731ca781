"""A chunk's message start and end time come from its message indexes in one C call
(protocol.ccodec.index_span) where numpy took two reductions a channel: the earliest and latest
log time whatever the order the messages came in, the same file as numpy's path, and errors for
buffers that are not (time, offset) pairs."""
from __future__ import annotations

from array import array

import numpy as np
import pytest
from mcap.records import Chunk, Message
from mcap.stream_reader import StreamReader, breakup_chunk

from hil.logs import mcap_writer
from hil.logs.mcap_writer import McapLog
from protocol import ccodec

pytestmark = pytest.mark.skipif(not ccodec.AVAILABLE or ccodec.index_span is None,
                                reason=ccodec.UNAVAILABLE_REASON or "an old _hilcodec build")


def _pairs(times, offset0=0):
    """A channel's index as the writer keeps it: native uint64 (time, offset) interleaved."""
    return array("Q", [v for i, t in enumerate(times) for v in (t, offset0 + 40 * i)])


def test_span_of_pairs_in_any_order():
    rng = np.random.default_rng(3)
    for _ in range(200):
        channels = [rng.integers(0, 2 ** 64 - 1, size=int(rng.integers(1, 40)), dtype=np.uint64,
                                 endpoint=True).tolist() for _ in range(int(rng.integers(1, 7)))]
        everything = [t for ch in channels for t in ch]
        # the offsets are larger than every time here: a span that read them would show it
        got = ccodec.index_span([_pairs(ch, offset0=2 ** 64 - 4096) for ch in channels])
        assert got == (min(everything), max(everything))


def test_span_skips_empty_channels_and_refuses_what_is_not_pairs():
    assert ccodec.index_span([array("Q"), _pairs([7, 3, 9]), array("Q")]) == (3, 9)
    with pytest.raises(ValueError, match="no \\(time, offset\\) pair"):
        ccodec.index_span([array("Q")])
    with pytest.raises(ValueError, match="buffer 1 holds 24 bytes"):
        ccodec.index_span([_pairs([1]), array("Q", [1, 2, 3])])
    with pytest.raises(TypeError):
        ccodec.index_span(5)


def _write(path, c_span: bool, monkeypatch) -> bytes:
    """Two channels whose messages go back and forth in time, over several chunks."""
    monkeypatch.setattr(mcap_writer, "_INDEX_SPAN", ccodec.index_span if c_span else None)
    log = McapLog(path, chunk_size=1024)
    a = log.add_fixed_channel("/a", "hil.A", [("x", "double")])
    for i in range(200):
        t = 1_000_000 + (i * 7919) % 1000 * 1000           # out of order within /a
        a.write_many(np.array([t], dtype=np.uint64), np.array([[float(i)]]))
        log.write_json("/b", 500_000 + 3 * i, {"i": i})    # earlier than every /a message
    log.close()
    monkeypatch.undo()
    return path.read_bytes()


def test_the_file_is_the_numpy_paths_and_its_chunks_span_their_messages(tmp_path, monkeypatch):
    c = _write(tmp_path / "c.mcap", True, monkeypatch)
    assert c == _write(tmp_path / "py.mcap", False, monkeypatch)
    chunks = 0
    with open(tmp_path / "c.mcap", "rb") as f:
        for record in StreamReader(f, emit_chunks=True, validate_crcs=True).records:
            if isinstance(record, Chunk):
                times = [m.log_time for m in breakup_chunk(record, validate_crc=True)
                         if isinstance(m, Message)]
                assert (record.message_start_time, record.message_end_time) == (min(times), max(times))
                chunks += 1
    assert chunks > 3
