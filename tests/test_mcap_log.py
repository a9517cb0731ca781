"""MCAP run log: hand-packed protobuf checked against google.protobuf, files checked with
the mcap package's readers, crash recovery (SIGKILL, truncation at every kind of record),
corruption and bad-path errors."""
from __future__ import annotations

import errno
import json
import os
import signal
import struct
import subprocess
import sys
import time
from pathlib import Path

import jsonschema
import numpy as np
import pytest
import zstandard
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
from mcap.data_stream import ReadDataStream
from mcap.reader import NonSeekingReader, SeekingReader
from mcap.records import Chunk, Message
from mcap.stream_reader import breakup_chunk

from hil.logs.reader import LogFileError, log_summary, read_log
from hil.logs.mcap_writer import FIXED_TYPES, McapLog

REPO = Path(__file__).resolve().parents[1]

# 18 fields: numbers 16-18 need two-byte tags; every fixed-width type appears
ALL_TYPES = [(f"d{i}", "double") for i in range(12)] + [
    ("f", "float"), ("u32", "fixed32"), ("s32", "sfixed32"), ("u64", "fixed64"), ("s64", "sfixed64"),
    ("d_last", "double")]


def _row(k: int) -> tuple:
    return (*[k * 0.1 + i * np.pi for i in range(12)], k / 3.0, k * 7, -k * 5, k * 2**33, -k * 2**40,
            -np.e * k)


def _message_class(schema) -> type:
    pool = descriptor_pool.DescriptorPool()
    for file in descriptor_pb2.FileDescriptorSet.FromString(schema.data).file:
        pool.Add(file)
    return message_factory.GetMessageClass(pool.FindMessageTypeByName(schema.name))


def _write_sample(path: Path, n: int = 3000, **kwargs) -> None:
    with McapLog(path, metadata={"profile": {"name": "paper-table-1", "pole_pairs": 1}}, **kwargs) as log:
        fixed = log.add_fixed_channel("/all/types", "hil.test.AllTypes", ALL_TYPES)
        frames = log.add_bytes_channel("/link/frames_in", "hil.FrameBatch")
        for k in range(n):
            fixed.write(k * 50_000, *_row(k))
            if k % 10 == 9:
                frames.write(k * 50_000, bytes([k % 256]) * (k % 50), 10)
            if k % 500 == 0:
                log.write_json("/plan/events", k * 50_000, {"kind": "step", "k": k, "value": k / 7,
                                                            "mixed": 0 if k == 0 else k / 3,  # int, then floats
                                                            "nested": {"a": 1.5, "ok": True}})
        log.add_attachment("plan.yaml", b"name: demo\n", "application/yaml")


def test_packed_protobuf_decodes_with_google_protobuf_to_the_same_values(tmp_path):
    path = tmp_path / "a.mcap"
    _write_sample(path, n=200)
    with open(path, "rb") as f:
        reader = SeekingReader(f, validate_crcs=True)
        seen = 0
        for schema, channel, message in reader.iter_messages(topics=["/all/types"]):
            msg = _message_class(schema).FromString(message.data)
            k = message.log_time // 50_000
            expected = _row(k)
            for (name, type_name), value in zip(ALL_TYPES, expected):
                got = getattr(msg, name)
                want = float(np.float32(value)) if type_name == "float" else value
                assert got == want, (name, k)
            # and our bytes are exactly what protobuf itself would serialize
            assert msg.SerializeToString() == message.data or k == 0
            seen += 1
    assert seen == 200


def test_bytes_channel_decodes_with_google_protobuf(tmp_path):
    path = tmp_path / "a.mcap"
    _write_sample(path, n=200)
    with open(path, "rb") as f:
        reader = SeekingReader(f, validate_crcs=True)
        batches = [(_message_class(s).FromString(m.data), m.log_time)
                   for s, _, m in reader.iter_messages(topics=["/link/frames_in"])]
    assert len(batches) == 20
    for msg, log_time in batches:
        k = log_time // 50_000
        assert msg.count == 10
        assert msg.data == bytes([k % 256]) * (k % 50)


def test_file_is_valid_for_the_mcap_package_and_every_schema_is_usable(tmp_path):
    path = tmp_path / "a.mcap"
    _write_sample(path)
    with open(path, "rb") as f:
        reader = SeekingReader(f, validate_crcs=True)
        summary = reader.get_summary()
        assert summary.statistics.message_count == 3000 + 300 + 6
        counts = {summary.channels[c].topic: n for c, n in summary.statistics.channel_message_counts.items()}
        assert counts == {"/all/types": 3000, "/link/frames_in": 300, "/plan/events": 6}
        assert summary.statistics.message_start_time == 0
        assert summary.statistics.message_end_time == 2999 * 50_000
        for channel in summary.channels.values():
            schema = summary.schemas[channel.schema_id]
            if channel.message_encoding == "protobuf":
                assert schema.encoding == "protobuf"
                _message_class(schema)  # the FileDescriptorSet defines the named message
            else:
                assert (channel.message_encoding, schema.encoding) == ("json", "jsonschema")
                jsonschema.Draft202012Validator.check_schema(json.loads(schema.data))
        for schema, channel, message in reader.iter_messages(topics=["/plan/events"]):
            jsonschema.validate(json.loads(message.data), json.loads(schema.data))
        assert [m.name for m in reader.iter_metadata()] == ["profile"]
        assert [a.name for a in reader.iter_attachments()] == ["plan.yaml"]
    with open(path, "rb") as f:  # streaming reader, data-section and chunk CRCs checked
        n = sum(1 for _ in NonSeekingReader(f, validate_crcs=True).iter_messages(log_time_order=False))
    assert n == 3306


def test_chunk_and_message_indexes_point_at_the_right_records(tmp_path):
    """What Foxglove's indexed reader relies on: every message index entry names the
    offset of a message of that channel and log time inside its chunk."""
    path = tmp_path / "a.mcap"
    _write_sample(path, n=3000, chunk_size=8 * 1024, compression="zstd")
    checked = 0
    with open(path, "rb") as f:
        summary = SeekingReader(f).get_summary()
        assert len(summary.chunk_indexes) == summary.statistics.chunk_count > 10
        for index in summary.chunk_indexes:
            f.seek(index.chunk_start_offset)
            assert f.read(1) == b"\x06"  # a Chunk record starts there
            chunk = Chunk.read(ReadDataStream(_skip(f, 8)))
            assert (chunk.message_start_time, chunk.message_end_time) == (index.message_start_time,
                                                                          index.message_end_time)
            records = zstandard.ZstdDecompressor().decompress(chunk.data, max_output_size=chunk.uncompressed_size)
            for channel_id, offset in index.message_index_offsets.items():
                f.seek(offset)
                opcode, length = struct.unpack("<BQ", f.read(9))
                assert opcode == 7  # MessageIndex
                cid, nbytes = struct.unpack("<HI", f.read(6))
                assert cid == channel_id and length == 6 + nbytes
                entries = struct.unpack(f"<{nbytes // 8}Q", f.read(nbytes))
                for log_time, at in zip(entries[0::2], entries[1::2]):
                    op, _, msg_cid, _, msg_time = struct.unpack_from("<BQHIQ", records, at)
                    assert (op, msg_cid, msg_time) == (5, channel_id, log_time)
                    checked += 1
    assert checked == 3000 + 300 + 6


def _skip(f, n: int):
    f.read(n)
    return f


@pytest.mark.parametrize("compression", ["zstd", "lz4", "none"])
def test_read_log_returns_exactly_what_was_written(tmp_path, compression):
    path = tmp_path / "a.mcap"
    _write_sample(path, compression=compression, chunk_size=16 * 1024)
    data = read_log(path)
    assert data.complete and data.truncated_at is None
    fixed = data["/all/types"]
    rows = np.array([_row(k) for k in range(3000)], dtype=object)
    for i, (name, type_name) in enumerate(ALL_TYPES):
        want = rows[:, i].astype(np.float32 if type_name == "float" else
                                 {"fixed32": np.uint32, "sfixed32": np.int32, "fixed64": np.uint64,
                                  "sfixed64": np.int64}.get(type_name, np.float64))
        np.testing.assert_array_equal(fixed[name], want, err_msg=name)
    np.testing.assert_array_equal(fixed.log_time_ns, np.arange(3000) * 50_000)
    np.testing.assert_allclose(fixed.t_s, np.arange(3000) * 50e-6, rtol=0, atol=1e-12)
    frames = data["/link/frames_in"]
    assert list(frames["count"]) == [10] * 300
    assert frames["data"][3] == bytes([39]) * 39
    events = data["/plan/events"]
    assert list(events["k"]) == [0, 500, 1000, 1500, 2000, 2500]
    assert list(events["nested.ok"]) == [True] * 6
    assert list(events["kind"]) == ["step"] * 6


def test_time_window_and_topic_selection(tmp_path):
    path = tmp_path / "a.mcap"
    _write_sample(path, chunk_size=4096)
    data = read_log(path, ["/all/types"], t0=0.01, t1=0.02)
    assert list(data) == ["/all/types"]
    t = data["/all/types"].t_s
    assert t[0] == pytest.approx(0.01) and t[-1] == pytest.approx(0.02) and len(t) == 201
    with pytest.raises(KeyError, match="no topic /nope; topics: /all/types"):
        read_log(path, ["/nope"])


def test_same_writes_give_identical_files(tmp_path):
    _write_sample(tmp_path / "a.mcap")
    _write_sample(tmp_path / "b.mcap")
    assert (tmp_path / "a.mcap").read_bytes() == (tmp_path / "b.mcap").read_bytes()


def test_json_channel_nan_becomes_null_and_numpy_values_serialize(tmp_path):
    path = tmp_path / "a.mcap"
    with McapLog(path) as log:
        log.write_json("/rt/stats", 0, {"lateness_us": np.float64(12.5), "hist": np.arange(3),
                                        "bad": float("nan"), "inf": [1.0, float("inf")]})
    with open(path, "rb") as f:
        (_, _, message), = SeekingReader(f).iter_messages()
    assert json.loads(message.data) == {"lateness_us": 12.5, "hist": [0, 1, 2], "bad": None, "inf": [1.0, None]}


def test_wrong_values_name_the_topic_and_fields(tmp_path):
    with McapLog(tmp_path / "a.mcap") as log:
        ch = log.add_fixed_channel("/plant/truth", "hil.T", [("speed_rpm", "double"), ("n", "fixed32")])
        with pytest.raises(ValueError, match=r"/plant/truth: expected 2 values \(speed_rpm, n\), got 1"):
            ch.write(0, 1.0)
        with pytest.raises(ValueError, match="/plant/truth: a value does not fit"):
            ch.write(0, 1.0, -1)  # fixed32 is unsigned
        with pytest.raises(ValueError, match="'int8'.*fixed-width types are double, float"):
            log.add_fixed_channel("/x", "hil.X", [("a", "int8")])
        with pytest.raises(ValueError, match="/plant/truth already has a channel"):
            log.add_fixed_channel("/plant/truth", "hil.T", [("a", "double")])
        with pytest.raises(ValueError, match="/plant/truth is a protobuf channel"):
            log.write_json("/plant/truth", 0, {"a": 1})
        ch.write(0, 2.0, 3)  # the failed writes left nothing behind
    assert len(read_log(tmp_path / "a.mcap")["/plant/truth"]) == 1


def test_writing_after_close_is_an_error(tmp_path):
    log = McapLog(tmp_path / "a.mcap")
    ch = log.add_fixed_channel("/plant/truth", "hil.T", [("x", "double")])
    ch.write(0, 1.0)
    log.close()
    with pytest.raises(ValueError, match="a.mcap is closed"):
        ch.write(1, 2.0)
    with pytest.raises(ValueError, match="is closed"):
        log.write_json("/cmd", 1, {"a": 1})
    assert len(read_log(tmp_path / "a.mcap")["/plant/truth"]) == 1 and read_log(tmp_path / "a.mcap").complete


def test_unwritable_path_raises_oserror_naming_the_path(tmp_path):
    missing = tmp_path / "no" / "such" / "dir" / "run.mcap"
    with pytest.raises(FileNotFoundError, match="cannot create MCAP log.*no/such/dir/run.mcap"):
        McapLog(missing)
    with pytest.raises(IsADirectoryError, match=str(tmp_path)):
        McapLog(tmp_path)
    with pytest.raises(OSError, match="cannot write MCAP log: No space left on device.*/dev/full") as info:
        McapLog("/dev/full")
    assert info.value.errno == errno.ENOSPC


class _FillsUp:
    """A file that accepts `room` bytes and then fails like a full disk."""

    def __init__(self, file, room: int):
        self.file, self.room = file, room
        self.closed = False

    def write(self, data):
        if len(data) > self.room:
            raise OSError(errno.ENOSPC, "No space left on device")
        self.room -= len(data)
        return self.file.write(data)

    def close(self):
        self.closed = True
        self.file.close()


def test_disk_full_mid_run_raises_once_and_keeps_what_was_written(tmp_path):
    path = tmp_path / "a.mcap"
    log = McapLog(path, chunk_size=4096)
    log._file = _FillsUp(log._file, room=20_000)
    ch = log.add_fixed_channel("/plant/truth", "hil.T", [("x", "double")])
    with pytest.raises(OSError, match=f"No space left on device.*{path.name}"):
        for k in range(100_000):
            ch.write(k, float(k))
    with pytest.raises(OSError, match="failed earlier"):
        log.flush()
    log.close()  # does not raise again: the first error is the one reported
    log.close()
    data = read_log(path)
    assert not data.complete
    x = data["/plant/truth"]["x"]
    assert len(x) > 500 and np.array_equal(x, np.arange(len(x)))


def test_unfinished_file_keeps_all_but_the_open_chunk(tmp_path):
    """The crash-loss bound: without close() or flush(), at most one chunk is missing."""
    path = tmp_path / "a.mcap"
    log = McapLog(path, chunk_size=64 * 1024)
    ch = log.add_fixed_channel("/plant/truth", "hil.T", [(f"f{i}", "double") for i in range(20)])
    n = 10_000
    for k in range(n):
        ch.write(k * 50_000, *([float(k)] * 20))
    per_chunk = 64 * 1024 // ch.record_size + 1
    data = read_log(path)  # the writer is still open: no summary, no footer
    assert not data.complete and "writer did not finish" in data.note
    got = data["/plant/truth"]["f0"]
    assert n - per_chunk <= len(got) < n
    assert np.array_equal(got, np.arange(len(got)))
    log.flush()
    assert len(read_log(path)["/plant/truth"]) == n
    log.close()
    assert read_log(path).complete


_CHILD = """
import sys, time
from hil.logs.mcap_writer import McapLog
log = McapLog(sys.argv[1], metadata={"run": {"who": "child"}})
ch = log.add_fixed_channel("/plant/truth", "hil.T", [("k", "fixed64"), ("x", "double")])
k = 0
while True:
    ch.write(k * 50_000, k, k * 0.5)
    if k == 0:   # one event, in the first chunk: the writer may pass any k before the kill
        log.write_json("/plan/events", k * 50_000, {"k": k})
    k += 1
    if k == 30_000:
        print("ready", flush=True)
"""


def test_sigkilled_writer_leaves_a_log_readable_up_to_its_last_finished_chunk(tmp_path):
    path = tmp_path / "killed.mcap"
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    child = subprocess.Popen([sys.executable, "-c", _CHILD, str(path)], stdout=subprocess.PIPE, env=env, cwd=REPO)
    try:
        assert child.stdout.readline().strip() == b"ready"
        time.sleep(0.05)
    finally:
        child.send_signal(signal.SIGKILL)
        child.wait(10)
    assert child.returncode == -signal.SIGKILL
    summary = log_summary(path)
    assert not summary["complete"] and summary["metadata"] == {"run": {"who": "child"}}
    data = read_log(path)
    k = data["/plant/truth"]["k"]
    assert len(k) >= 30_000 - 64 * 1024 // 49
    assert np.array_equal(k, np.arange(len(k)))  # no gap, no garbage
    assert np.array_equal(data["/plant/truth"]["x"], k * 0.5)
    assert list(data["/plan/events"]["k"]) == [0]
    assert summary["channels"][0]["count"] == len(k)
    # the mcap package's streaming reader agrees (it raises at the cut, after the last chunk)
    with open(path, "rb") as f:
        streamed = 0
        try:
            for _, channel, _ in NonSeekingReader(f).iter_messages(log_time_order=False):
                streamed += channel.topic == "/plant/truth"
        except Exception:
            pass
    assert streamed == len(k)


def _chunk_layout(path: Path) -> list[tuple[int, int]]:
    """(end offset, message count) of every chunk, as the mcap package reads them."""
    out = []
    with open(path, "rb") as f:
        summary = SeekingReader(f).get_summary()
        for index in sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset):
            f.seek(index.chunk_start_offset + 9)
            chunk = Chunk.read(ReadDataStream(f))
            out.append((index.chunk_start_offset + index.chunk_length,
                        sum(isinstance(r, Message) for r in breakup_chunk(chunk))))
    return out


def test_truncation_anywhere_yields_the_finished_chunks(tmp_path):
    """Cut a finished file inside every kind of record: the reader returns the messages
    of exactly the chunks that end before the cut."""
    path = tmp_path / "full.mcap"
    _write_sample(path, n=2000, chunk_size=8 * 1024)
    blob = path.read_bytes()
    layout = _chunk_layout(path)
    ends = [end for end, _ in layout]
    cuts = {9, 40, 300, ends[0] - 1, ends[0], ends[0] + 5, ends[3] + 100, (ends[5] + ends[6]) // 2,
            ends[-1] + 40, len(blob) - 600, len(blob) - 30, len(blob) - 3}
    for cut in sorted(cuts):
        (tmp_path / "cut.mcap").write_bytes(blob[:cut])
        data = read_log(tmp_path / "cut.mcap")
        expected = sum(n for end, n in layout if end <= cut)
        assert sum(len(td) for td in data.values()) == expected, cut
        assert not data.complete and data.truncated_at is not None
        assert log_summary(tmp_path / "cut.mcap")["message_count"] == expected


def test_corrupted_or_foreign_files_raise_naming_the_file(tmp_path):
    path = tmp_path / "a.mcap"
    _write_sample(path, n=2000, chunk_size=8 * 1024)
    blob = bytearray(path.read_bytes())
    with open(path, "rb") as f:
        index = sorted(SeekingReader(f).get_summary().chunk_indexes, key=lambda c: c.chunk_start_offset)[2]
    bad = tmp_path / "bad.mcap"
    flipped = blob.copy()
    flipped[index.chunk_start_offset + index.chunk_length - 100] ^= 0x40  # inside the compressed data
    bad.write_bytes(flipped)
    with pytest.raises(LogFileError, match=rf"{bad}: corrupted chunk at byte {index.chunk_start_offset}"):
        read_log(bad)
    flipped = blob.copy()
    flipped[index.chunk_start_offset + 10] ^= 0x01  # the chunk's start time: only the data CRC sees it
    bad.write_bytes(flipped)
    with pytest.raises(LogFileError, match="data section .* fails its CRC"):
        log_summary(bad)
    flipped = blob.copy()
    flipped[index.chunk_start_offset] = 0x55  # not an opcode
    bad.write_bytes(flipped)
    with pytest.raises(LogFileError, match=rf"invalid record opcode 0x55 at byte {index.chunk_start_offset}"):
        read_log(bad)
    other = tmp_path / "notes.mcap"
    other.write_text("just some text, not a log\n")
    with pytest.raises(LogFileError, match=rf"{other}: not an MCAP file"):
        log_summary(other)
    empty = tmp_path / "empty.mcap"
    empty.write_bytes(b"")
    with pytest.raises(LogFileError, match=rf"{empty}: empty file"):
        read_log(empty)
    with pytest.raises(FileNotFoundError, match="missing.mcap"):
        read_log(tmp_path / "missing.mcap")


def test_fixed_types_table_matches_protobuf_wire_sizes():
    for name, (ftype, wire, code) in FIXED_TYPES.items():
        size = {"d": 8, "q": 8, "Q": 8, "f": 4, "i": 4, "I": 4}[code]
        assert (wire == 1) == (size == 8), name


def test_reader_takes_files_of_other_writers(tmp_path):
    """A file from the mcap package's own Writer (schemas and channels inside chunks, a
    protobuf message with varint and string fields) decodes through the generic paths."""
    from mcap.writer import Writer

    f = descriptor_pb2.FieldDescriptorProto
    file = descriptor_pb2.FileDescriptorProto(name="x/Status.proto", package="x", syntax="proto3")
    msg = file.message_type.add(name="Status")
    msg.field.add(name="label", number=1, type=f.TYPE_STRING, label=f.LABEL_OPTIONAL)
    msg.field.add(name="count", number=2, type=f.TYPE_INT32, label=f.LABEL_OPTIONAL)
    msg.field.add(name="value", number=3, type=f.TYPE_DOUBLE, label=f.LABEL_OPTIONAL)
    fds = descriptor_pb2.FileDescriptorSet(file=[file])
    schema = type("S", (), {"data": fds.SerializeToString(), "name": "x.Status"})
    cls = _message_class(schema)
    path = tmp_path / "foreign.mcap"
    with open(path, "wb") as out:
        writer = Writer(out, chunk_size=512)
        writer.start()
        pb = writer.register_channel("/status", "protobuf",
                                     writer.register_schema("x.Status", "protobuf", fds.SerializeToString()))
        js = writer.register_channel("/note", "json", writer.register_schema("note", "jsonschema", b"{}"))
        for k in range(100):
            writer.add_message(pb, 1_000 + k * 10, cls(label=f"s{k}", count=-k, value=k / 4).SerializeToString(),
                               1_000 + k * 10)
            if k % 10 == 0:
                writer.add_message(js, 1_000 + k * 10, json.dumps({"k": k, "deep": {"x": [k]}}).encode(),
                                   1_000 + k * 10)
        writer.finish()
    data = read_log(path)
    assert data.complete and data.start_ns == 1_000
    status = data["/status"]
    assert list(status["label"][:3]) == ["s0", "s1", "s2"]
    assert status["count"].dtype == np.int64 and list(status["count"][:3]) == [0, -1, -2]
    np.testing.assert_array_equal(status["value"], np.arange(100) / 4)
    np.testing.assert_allclose(status.t_s, np.arange(100) * 10e-9)
    note = data["/note"]
    assert list(note["k"]) == list(range(0, 100, 10)) and note["deep.x"][1] == [10]
    windowed = read_log(path, ["/status"], t0=500e-9, t1=600e-9)["/status"]
    assert list(windowed["count"]) == [-50, -51, -52, -53, -54, -55, -56, -57, -58, -59, -60]


def test_write_many_gives_the_same_file_as_one_write_per_message(tmp_path):
    """The batched path (numpy columns into the chunk) writes the very bytes write() does,
    across chunk boundaries, in batches of any size."""
    n = 1000
    values = np.column_stack([np.arange(n), np.arange(n) * 0.5, np.arange(n) * 0.25])
    times = np.arange(n) * 50_000
    files = []
    for mode in ("one", "many"):
        path = tmp_path / f"{mode}.mcap"
        log = McapLog(path, chunk_size=4096)
        ch = log.add_fixed_channel("/a", "hil.A", [("k", "fixed32"), ("x", "double"), ("y", "float")])
        if mode == "one":
            for i in range(n):
                ch.write(int(times[i]), int(values[i, 0]), values[i, 1], values[i, 2])
        else:
            for a in range(0, n, 137):
                ch.write_many(times[a:a + 137], values[a:a + 137])
        log.close()
        files.append(path.read_bytes())
    assert files[0] == files[1]
    assert read_log(tmp_path / "many.mcap")["/a"]["x"].tolist() == (np.arange(n) * 0.5).tolist()


def test_write_many_refuses_values_that_do_not_fit(tmp_path):
    log = McapLog(tmp_path / "bad.mcap")
    ch = log.add_fixed_channel("/s", "hil.S", [("k", "fixed32"), ("x", "double")])
    with pytest.raises(ValueError, match="/s: a value does not fit.*'k' = -1.0: outside 0..4294967295"):
        ch.write_many([0, 1], [[1, 0.0], [-1, 0.0]])          # fixed32 cannot hold -1
    with pytest.raises(ValueError, match="'k' = 2.5: a whole number is expected"):
        ch.write_many([0, 1], [[1, 0.0], [2.5, 0.0]])
    with pytest.raises(ValueError, match="'k' = nan: a whole number is expected"):
        ch.write_many([0, 1], [[float("nan"), 0.0], [2, 0.0]])
    with pytest.raises(ValueError, match="'k' = 4294967296.0: outside"):
        ch.write_many([0], [[2.0 ** 32, 0.0]])
    with pytest.raises(ValueError, match="/s: expected 2 rows of 2 values"):
        ch.write_many([0, 1], [[1, 0.0, 3.0], [2, 0.0, 3.0]])
    log.close()


def _protobuf_descriptor_set(message_name: str, fields: list[tuple[str, int]]) -> bytes:
    """What the writer serialized with google.protobuf before it packed the schemas itself."""
    package, _, short = message_name.rpartition(".")
    file = descriptor_pb2.FileDescriptorProto(
        name=message_name.replace(".", "/") + ".proto", package=package, syntax="proto3")
    msg = file.message_type.add(name=short)
    for number, (name, type_number) in enumerate(fields, start=1):
        msg.field.add(name=name, number=number, type=type_number,
                      label=descriptor_pb2.FieldDescriptorProto.LABEL_OPTIONAL)
    return descriptor_pb2.FileDescriptorSet(file=[file]).SerializeToString()


@pytest.mark.parametrize("message_name", ["hil.PlantTruth", "Bare", "a.b.c.Deep"])
def test_hand_serialized_schemas_are_the_bytes_google_protobuf_writes(message_name):
    """The writer builds its FileDescriptorSets without importing descriptor_pb2 (~30 ms of a
    run's start): byte for byte what google.protobuf serializes, for every fixed type, field
    numbers past 15 (two-byte tags), a message longer than 127 bytes (two-byte lengths) and an
    empty package."""
    from hil.logs.mcap_writer import bytes_descriptor_set, fixed_descriptor_set

    f = descriptor_pb2.FieldDescriptorProto
    for name, (type_number, _, _) in FIXED_TYPES.items():
        assert type_number == getattr(f, f"TYPE_{name.upper()}"), name
    for fields in (ALL_TYPES[:1], ALL_TYPES, ALL_TYPES * 9):
        fields = [(f"{n}_{i}", t) for i, (n, t) in enumerate(fields)]
        assert fixed_descriptor_set(message_name, fields) == _protobuf_descriptor_set(
            message_name, [(n, FIXED_TYPES[t][0]) for n, t in fields])
    assert bytes_descriptor_set(message_name) == _protobuf_descriptor_set(
        message_name, [("count", f.TYPE_FIXED32), ("data", f.TYPE_BYTES)])


def test_the_logs_crc32_is_zlibs_on_both_sides_of_the_isal_threshold():
    """mcap_writer.crc32 hands big buffers to ISA-L: the same CRC-32 as zlib's (MCAP's), for
    every length around the hand-over, from any starting CRC, for bytes and memoryview slices;
    and a file whose chunks are over the threshold passes the mcap package's CRC checks."""
    import zlib

    from hil.logs import mcap_writer

    data = np.random.default_rng(3).integers(0, 256, mcap_writer._ISAL_CRC_FROM + 70_000,
                                              dtype=np.uint8).tobytes()
    edge = mcap_writer._ISAL_CRC_FROM
    for n in (0, 1, 9, edge - 1, edge, edge + 1, edge + 65_536):
        for start in (0, 0xDEADBEEF):
            assert mcap_writer.crc32(data[:n], start) == zlib.crc32(data[:n], start), (n, start)
            assert mcap_writer.crc32(memoryview(data)[3:3 + n], start) == zlib.crc32(data[3:3 + n], start)
    assert mcap_writer.crc32(b"123456789") == 0xCBF43926      # the CRC-32 check value
    assert mcap_writer._isal_crc32 is not None                 # the big buffers went to ISA-L


def test_a_log_of_full_chunks_passes_the_mcap_packages_crc_checks(tmp_path):
    path = tmp_path / "big.mcap"
    log = McapLog(path, chunk_size=64 * 1024)
    ch = log.add_fixed_channel("/x", "hil.X", [("a", "double"), ("b", "double")])
    rng = np.random.default_rng(5)
    ch.write_many(np.arange(20_000, dtype=np.uint64) * 1000, rng.standard_normal((20_000, 2)))
    log.close()
    with open(path, "rb") as f:
        messages = list(SeekingReader(f, validate_crcs=True).iter_messages())
    assert len(messages) == 20_000
    assert len(read_log(path)["/x"].fields["a"]) == 20_000


def test_a_bytes_message_larger_than_the_chunk_buffer_and_a_bytearray_payload(tmp_path):
    """A raw-frame batch is copied into the open chunk in place, growing the chunk's buffer only
    for a message longer than it (here 3x the buffer, after a small one); the payload may be a
    bytearray (the link tap's capture buffer) and is read back byte for byte."""
    path = tmp_path / "big.mcap"
    small = bytearray(range(7))
    big = bytes((i * 7) % 251 for i in range(3 * (4096 + 64 * 1024)))
    with McapLog(path, chunk_size=4096) as log:
        frames = log.add_bytes_channel("/link/frames_in", "hil.FrameBatch")
        frames.write(1_000, small, 2)
        frames.write(2_000, big, 9)
        frames.write(3_000, b"", 0)
    with open(path, "rb") as f:
        reader = SeekingReader(f, validate_crcs=True)
        got = [(_message_class(s).FromString(m.data), m.log_time) for s, _, m in reader.iter_messages()]
    assert [(bytes(msg.data), msg.count, t) for msg, t in got] == [
        (bytes(small), 2, 1_000), (big, 9, 2_000), (b"", 0, 3_000)]
