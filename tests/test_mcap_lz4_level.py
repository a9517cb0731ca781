"""The log's lz4 chunks are compressed at the level asked for (the writer's LZ4_LEVEL by
default), and whatever the level the mcap package reads them back."""
from __future__ import annotations

from pathlib import Path

import lz4.frame
import pytest
from mcap.data_stream import ReadDataStream
from mcap.reader import SeekingReader
from mcap.records import Chunk

from hil.logs.mcap_writer import LZ4_LEVEL, McapLog


def _write(path: Path, **options) -> None:
    log = McapLog(path, compression="lz4", chunk_size=4096, **options)
    ch = log.add_fixed_channel("/t", "hil.T", [("k", "fixed32"), ("x", "double")])
    for k in range(2000):
        ch.write(k * 1000, k, (k % 97) * 0.25)
    log.close()


def _chunks(path: Path) -> list[Chunk]:
    with open(path, "rb") as f:
        summary = SeekingReader(f).get_summary()
        out = []
        for index in sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset):
            f.seek(index.chunk_start_offset + 9)
            out.append(Chunk.read(ReadDataStream(f)))
    return out


@pytest.mark.parametrize("options, level", [({}, LZ4_LEVEL), ({"lz4_level": 0}, 0)])
def test_chunks_are_lz4_frames_at_the_level_asked_for(tmp_path, options, level):
    path = tmp_path / "log.mcap"
    _write(path, **options)
    chunks = _chunks(path)
    assert len(chunks) > 3
    for chunk in chunks:
        raw = lz4.frame.decompress(chunk.data)
        assert chunk.compression == "lz4" and len(raw) == chunk.uncompressed_size
        # the same bytes as lz4 makes at that level, and not those of the other level
        assert chunk.data == lz4.frame.compress(raw, compression_level=level)
    other = 0 if level == LZ4_LEVEL else LZ4_LEVEL
    assert any(c.data != lz4.frame.compress(lz4.frame.decompress(c.data), compression_level=other)
               for c in chunks)
    with open(path, "rb") as f:
        got = [(m.log_time, ch.topic) for _, ch, m in SeekingReader(f).iter_messages()]
    assert got == [(k * 1000, "/t") for k in range(2000)]
