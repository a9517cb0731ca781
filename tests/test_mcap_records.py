"""hil.logs.mcap_records writes the bytes the mcap package's writer writes: each record kind
against the package's record class with the same fields, and a whole log of the bench's
writer against the package re-serializing every record it reads from that log."""
from __future__ import annotations

import io

import pytest
from mcap.data_stream import RecordBuilder
from mcap.opcode import Opcode
from mcap.records import (Attachment, AttachmentIndex, Channel, ChunkIndex, DataEnd, Header, Metadata,
                          MetadataIndex, Schema, Statistics, SummaryOffset)
from mcap.stream_reader import StreamReader

from hil.logs import mcap_records as rec
from hil.logs.mcap_writer import McapLog


def _mcap(record) -> bytes:
    rb = RecordBuilder()
    record.write(rb)
    return rb.end()


def test_opcodes_are_the_packages():
    for op in Opcode:
        assert getattr(rec, op.name) == op.value


@pytest.mark.parametrize("text", ["", "hil-bench mcap_log", "ünïcode ✓"])
def test_header(text):
    assert rec.header(text, "lib " + text) == _mcap(Header(profile=text, library="lib " + text))


@pytest.mark.parametrize("data", [b"", b"\x00\x01\xff" * 100])
def test_schema(data):
    assert rec.schema(7, "hil.PlantTruth", "protobuf", data) == _mcap(
        Schema(id=7, name="hil.PlantTruth", encoding="protobuf", data=data))


@pytest.mark.parametrize("metadata", [{}, {"a": "1", "ключ": "значение", "": ""}])
def test_channel_and_metadata(metadata):
    assert rec.channel(3, 2, "/plant/truth", "protobuf", metadata) == _mcap(
        Channel(id=3, schema_id=2, topic="/plant/truth", message_encoding="protobuf", metadata=metadata))
    assert rec.metadata("profile", metadata) == _mcap(Metadata(name="profile", metadata=metadata))


def test_index_records():
    assert rec.metadata_index(1234, 56, "run") == _mcap(MetadataIndex(offset=1234, length=56, name="run"))
    assert rec.attachment_index(10, 20, 30, 40, 50, "plan.yaml", "application/yaml") == _mcap(
        AttachmentIndex(offset=10, length=20, log_time=30, create_time=40, data_size=50,
                        name="plan.yaml", media_type="application/yaml"))
    offsets = {1: 2**40, 3: 17, 65535: 0}
    assert rec.chunk_index(1, 2**63, 3, 4, offsets, 5, "lz4", 6, 7) == _mcap(ChunkIndex(
        message_start_time=1, message_end_time=2**63, chunk_start_offset=3, chunk_length=4,
        message_index_offsets=offsets, message_index_length=5, compression="lz4",
        compressed_size=6, uncompressed_size=7))
    assert rec.chunk_index(0, 0, 0, 0, {}, 0, "", 0, 0) == _mcap(ChunkIndex(
        message_start_time=0, message_end_time=0, chunk_start_offset=0, chunk_length=0,
        message_index_offsets={}, message_index_length=0, compression="", compressed_size=0,
        uncompressed_size=0))


@pytest.mark.parametrize("data", [b"", b"name: demo\n" * 50])
def test_attachment_with_its_crc(data):
    assert rec.attachment(11, 22, "plan.yaml", "application/yaml", data) == _mcap(Attachment(
        create_time=22, log_time=11, name="plan.yaml", media_type="application/yaml", data=data))


def test_statistics_data_end_summary_offset():
    counts = {1: 20000, 2: 3, 9: 0}
    assert rec.statistics(20003, 4, 3, 1, 2, 5, 50_000, 2**62, counts) == _mcap(Statistics(
        message_count=20003, schema_count=4, channel_count=3, attachment_count=1, metadata_count=2,
        chunk_count=5, message_start_time=50_000, message_end_time=2**62, channel_message_counts=counts))
    assert rec.data_end(0xDEADBEEF) == _mcap(DataEnd(data_section_crc=0xDEADBEEF))
    assert rec.summary_offset(rec.CHUNK_INDEX, 1000, 234) == _mcap(
        SummaryOffset(group_opcode=Opcode.CHUNK_INDEX, group_start=1000, group_length=234))


def test_a_whole_log_is_what_the_package_writes_for_its_records(tmp_path):
    """Every record of a log (header, schemas, channels, chunks, message indexes, metadata,
    attachment, data end, summary, summary offsets, footer) read by the package and written
    again by it gives the file byte for byte."""
    path = tmp_path / "a.mcap"
    with McapLog(path, metadata={"profile": {"name": "paper", "pole_pairs": 1}}, chunk_size=1024) as log:
        fixed = log.add_fixed_channel("/plant/truth", "hil.Truth", [("t", "double"), ("k", "fixed32")])
        frames = log.add_bytes_channel("/link/frames_in", "hil.FrameBatch")
        for k in range(300):
            fixed.write(k * 50_000, k * 0.5, k)
            if k % 10 == 0:
                frames.write(k * 50_000, bytes([k % 256]) * (k % 7), 1)
            if k % 100 == 0:
                log.write_json("/plan/events", k * 50_000, {"kind": "step", "k": k})
        log.add_metadata("run", {"seed": 0, "plan": "demo"})
        log.add_attachment("plan.yaml", b"name: demo\n", "application/yaml", log_time_ns=5)
    data = path.read_bytes()
    records = list(StreamReader(io.BytesIO(data), emit_chunks=True, validate_crcs=True).records)
    kinds = {type(r).__name__ for r in records}
    assert {"Header", "Schema", "Channel", "Chunk", "MessageIndex", "Metadata", "Attachment", "DataEnd",
            "Statistics", "ChunkIndex", "MetadataIndex", "AttachmentIndex", "SummaryOffset",
            "Footer"} <= kinds
    assert rec.MAGIC + b"".join(_mcap(r) for r in records) + rec.MAGIC == data
