"""Read run logs (MCAP) into numpy columns, including files whose writer was killed.

The file is walked record by record in file order, the way the mcap package's
NonSeekingReader does (which is what recovers an unfinished file; the seeking reader
needs the summary at the end and finds nothing). A file that ends inside a record, or
has no footer, is *truncated*: every message of its finished chunks is returned and the
result says where the readable part ends. A file that is not MCAP, or whose finished
records are damaged (bad magic, CRC mismatch, chunk that does not decompress, impossible
record), raises :class:`LogFileError` naming the file and the byte offset.

Decoding: protobuf channels whose messages all have the fixed layout written by
:mod:`hil.logs.mcap_writer` are decoded in one go with a numpy structured dtype (every tag is
checked); any other protobuf message goes through google.protobuf; JSON through json,
nested objects flattened to ``a.b`` columns.
"""
from __future__ import annotations

import json
import mmap
import struct
import zlib
from array import array
from dataclasses import dataclass, field
from io import BytesIO
from pathlib import Path
from typing import Any, Iterable

import numpy as np
from google.protobuf import descriptor_pb2, descriptor_pool, json_format, message_factory
from mcap.data_stream import ReadDataStream
from mcap.opcode import Opcode
from mcap.records import Attachment, Channel, Header, Metadata, Schema

from hil.logs.mcap_writer import LIBRARY as OUR_LIBRARY

MCAP_MAGIC = b"\x89MCAP0\r\n"
_HEAD = struct.Struct("<BQ")
_MSG = struct.Struct("<BQHIQ")  # opcode, record length, channel id, sequence, log time
_MSG_PREFIX_LEN = 31  # + publish time
_CHUNK_HEAD = struct.Struct("<QQQII")
_KNOWN_OPCODES = {int(op) for op in Opcode}
_OP_MESSAGE = int(Opcode.MESSAGE)  # a plain int: compared once per message

_F = descriptor_pb2.FieldDescriptorProto
_FIXED_DTYPES = {_F.TYPE_DOUBLE: ("<f8", 1), _F.TYPE_FLOAT: ("<f4", 5), _F.TYPE_FIXED32: ("<u4", 5),
                 _F.TYPE_SFIXED32: ("<i4", 5), _F.TYPE_FIXED64: ("<u8", 1), _F.TYPE_SFIXED64: ("<i8", 1)}


class LogFileError(ValueError):
    """A file that is not a readable MCAP log; the message names the file."""


@dataclass
class TopicData:
    """One topic's messages as columns: ``log_time_ns``, ``t_s`` (seconds from the log's
    first message) and one array per field."""

    topic: str
    message_encoding: str
    schema_name: str
    log_time_ns: np.ndarray
    t_s: np.ndarray
    fields: dict[str, np.ndarray]

    def __getitem__(self, name: str) -> np.ndarray:
        if name == "log_time_ns":
            return self.log_time_ns
        if name == "t_s":
            return self.t_s
        try:
            return self.fields[name]
        except KeyError:
            raise KeyError(f"{self.topic} has no field {name!r}; "
                           f"fields: {', '.join(self.fields) or '(none)'}") from None

    def __len__(self) -> int:
        return len(self.log_time_ns)

    def __contains__(self, name: object) -> bool:
        return name in self.fields or name in ("log_time_ns", "t_s")


class LogData(dict):
    """topic -> TopicData, plus what is known about the file: ``path``, ``complete``
    (False for an unfinished file), ``truncated_at`` (byte offset where the readable
    part ends, or None), ``note`` and ``start_ns`` (log time of the first message)."""

    def __init__(self, path: Path, complete: bool, truncated_at: int | None, note: str, start_ns: int | None):
        super().__init__()
        self.path = path
        self.complete = complete
        self.truncated_at = truncated_at
        self.note = note
        self.start_ns = start_ns


# -- walking the file ------------------------------------------------------------------------

@dataclass
class _ChannelInfo:
    channel: Channel
    schema: Schema | None


@dataclass
class _Scan:
    path: Path
    size: int
    header: Header | None = None
    schemas: dict[int, Schema] = field(default_factory=dict)
    channels: dict[int, _ChannelInfo] = field(default_factory=dict)
    metadata: list[Metadata] = field(default_factory=list)
    attachments: list[tuple[str, str, int]] = field(default_factory=list)
    # (offset, end, message_start_ns, message_end_ns, is_chunk); loose messages have is_chunk False
    data_records: list[tuple[int, int, int, int, bool]] = field(default_factory=list)
    compressions: set[str] = field(default_factory=set)
    complete: bool = False
    truncated_at: int | None = None
    note: str = ""
    crc_error: str = ""  # raised after the walk, unless a more precise error came first

    def start_ns(self) -> int | None:
        return min((r[2] for r in self.data_records), default=None)


def _err(path: Path, msg: str) -> LogFileError:
    return LogFileError(f"{path}: {msg}")


class _DamagedRecord(ValueError):
    """A finished record whose body does not parse; _File turns it into a LogFileError."""


def _record(cls, body: bytes) -> Any:
    try:
        return cls.read(ReadDataStream(BytesIO(body)))
    except Exception as exc:  # noqa: BLE001 - mcap raises EndOfFile, struct.error, UnicodeDecodeError...
        raise _DamagedRecord(f"corrupted: a {cls.__name__} record does not parse "
                             f"({type(exc).__name__}: {exc})") from None


class _File:
    """An mmapped MCAP file and the first (index) pass over its top-level records."""

    def __init__(self, path: str | Path):
        self.path = Path(path)
        try:
            with open(self.path, "rb") as f:
                size = f.seek(0, 2)
                if size == 0:
                    raise _err(self.path, "empty file, not an MCAP log")
                self.buf = mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ)
        except IsADirectoryError:
            raise _err(self.path, "is a directory, not an MCAP log") from None
        try:
            self.scan = self._index_pass()
        except _DamagedRecord as exc:
            self.buf.close()
            raise _err(self.path, str(exc)) from None
        except BaseException:
            self.buf.close()
            raise

    def __enter__(self) -> _File:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        self.buf.close()
        if isinstance(exc, _DamagedRecord):
            raise _err(self.path, str(exc)) from None

    def _index_pass(self) -> _Scan:
        buf, path = self.buf, self.path
        size = len(buf)
        scan = _Scan(path=path, size=size)
        if size < 8 or buf[:8] != MCAP_MAGIC:
            raise _err(path, f"not an MCAP file (it starts with {bytes(buf[:8])!r}, not the MCAP magic)")
        pos = 8
        while pos < size:
            if pos + 9 > size:
                scan.truncated_at = pos
                scan.note = f"file ends inside a record header at byte {pos}: the writer did not finish it"
                return scan
            opcode, length = _HEAD.unpack_from(buf, pos)
            body, end = pos + 9, pos + 9 + length
            if opcode not in _KNOWN_OPCODES and opcode < 0x80:
                raise _err(path, f"corrupted: invalid record opcode 0x{opcode:02x} at byte {pos}")
            if end > size:
                name = Opcode(opcode).name if opcode in _KNOWN_OPCODES else hex(opcode)
                scan.truncated_at = pos
                scan.note = (f"file ends inside a {name} record at byte {pos} ({size - body} of "
                             f"{length} bytes present): the writer did not finish it")
                return scan
            try:
                if opcode == Opcode.CHUNK:
                    start_ns, end_ns = struct.unpack_from("<QQ", buf, body)
                    scan.data_records.append((pos, end, start_ns, end_ns, True))
                elif opcode == Opcode.MESSAGE:
                    log_time = _MSG.unpack_from(buf, pos)[4]
                    scan.data_records.append((pos, end, log_time, log_time, False))
                elif opcode == Opcode.HEADER:
                    scan.header = _record(Header, buf[body:end])
                elif opcode == Opcode.SCHEMA:
                    schema = _record(Schema, buf[body:end])
                    scan.schemas[schema.id] = schema
                elif opcode == Opcode.CHANNEL:
                    self._add_channel(scan, _record(Channel, buf[body:end]), pos)
                elif opcode == Opcode.METADATA:
                    scan.metadata.append(_record(Metadata, buf[body:end]))
                elif opcode == Opcode.ATTACHMENT:
                    att = _record(Attachment, buf[body:end])
                    scan.attachments.append((att.name, att.media_type, len(att.data)))
                elif opcode in (Opcode.DATA_END, Opcode.FOOTER):
                    if opcode == Opcode.DATA_END:
                        (crc,) = struct.unpack_from("<I", buf, body)
                        view = memoryview(buf)
                        try:
                            if crc and zlib.crc32(view[:pos]) != crc:
                                scan.crc_error = f"corrupted: the data section (bytes 0-{pos}) fails its CRC"
                        finally:
                            view.release()
                    scan.complete = size >= 8 + 37 and buf[size - 8:] == MCAP_MAGIC and buf[size - 37] == Opcode.FOOTER
                    if not scan.complete:
                        scan.truncated_at = end
                        scan.note = "file ends in its summary section (no footer): the writer did not finish it"
                    return scan
            except LogFileError:
                raise
            except (struct.error, UnicodeDecodeError, ValueError) as exc:
                raise _err(path, f"corrupted {Opcode(opcode).name} record at byte {pos} ({exc})") from None
            pos = end
        scan.truncated_at = size
        scan.note = "file ends without a data-end record or footer: the writer did not finish it"
        return scan

    def _add_channel(self, scan: _Scan, channel: Channel, pos: int) -> None:
        if channel.schema_id and channel.schema_id not in scan.schemas:
            raise _err(self.path, f"corrupted: channel {channel.topic} at byte {pos} refers to "
                                  f"schema {channel.schema_id}, which is not defined before it")
        scan.channels[channel.id] = _ChannelInfo(channel, scan.schemas.get(channel.schema_id))

    def chunk_records(self, pos: int, end: int) -> bytes:
        """The decompressed records of the chunk at `pos`, CRC checked."""
        buf, path = self.buf, self.path
        body = pos + 9
        try:
            _, _, raw_size, crc, clen = _CHUNK_HEAD.unpack_from(buf, body)
            p = body + _CHUNK_HEAD.size
            compression = bytes(buf[p:p + clen]).decode("utf-8")
            p += clen
            (dlen,) = struct.unpack_from("<Q", buf, p)
        except (struct.error, UnicodeDecodeError) as exc:
            raise _err(path, f"corrupted chunk at byte {pos} ({exc})") from None
        p += 8
        if p + dlen != end:
            raise _err(path, f"corrupted chunk at byte {pos}: its data length ({dlen}) does not match the record")
        self.scan.compressions.add(compression or "none")
        try:
            if compression == "zstd":
                import zstandard
                raw = zstandard.ZstdDecompressor().decompress(buf[p:end], max_output_size=raw_size)
            elif compression == "lz4":
                import lz4.frame
                raw = lz4.frame.decompress(buf[p:end])
            elif compression == "":
                raw = buf[p:end]
            else:
                raise _err(path, f"chunk at byte {pos} uses compression {compression!r}, which is not supported")
        except LogFileError:
            raise
        except Exception as exc:  # zstandard and lz4 raise their own error types
            raise _err(path, f"corrupted chunk at byte {pos}: its {compression} data does not "
                             f"decompress ({exc})") from None
        if len(raw) != raw_size:
            raise _err(path, f"corrupted chunk at byte {pos}: {len(raw)} bytes decompressed, {raw_size} expected")
        if crc and zlib.crc32(raw) != crc:
            raise _err(path, f"corrupted chunk at byte {pos}: CRC mismatch")
        return raw

    def walk(self, targets: dict[int, Any], collect_records: bool, window: tuple[int, int] | None = None,
             on_channel=None) -> None:
        """Append every message of the channels in `targets` to ``targets[id]``: the whole
        record bytes if `collect_records`, else its log time. Chunks entirely outside
        `window` (log-time ns) are skipped when that is safe (our writer puts schemas and
        channels outside chunks)."""
        scan = self.scan
        skip_ok = scan.header is not None and scan.header.library.startswith(OUR_LIBRARY)
        for pos, end, t_first, t_last, is_chunk in scan.data_records:
            if window is not None and skip_ok and (t_last < window[0] or t_first > window[1]):
                continue
            if is_chunk:
                records = self.chunk_records(pos, end)
                self._walk_records(records, 0, len(records), targets, collect_records, pos, on_channel)
            else:
                self._walk_records(self.buf, pos, end, targets, collect_records, pos, on_channel)
        if scan.crc_error:
            raise _err(self.path, scan.crc_error)

    def _walk_records(self, data, pos: int, stop: int, targets, collect_records: bool, where: int,
                      on_channel) -> None:
        unpack = _MSG.unpack_from
        channels = self.scan.channels
        while pos < stop:
            try:
                opcode, length, cid, _seq, log_time = unpack(data, pos)
            except struct.error:  # a record shorter than a message header: only legal at the very end
                if pos + 9 > stop:
                    raise _err(self.path, f"corrupted chunk at byte {where}: record header cut short") from None
                opcode, length = _HEAD.unpack_from(data, pos)
                cid = log_time = 0
            end = pos + 9 + length
            if end > stop:
                raise _err(self.path, f"corrupted chunk at byte {where}: a record overruns it")
            if opcode == _OP_MESSAGE:
                target = targets.get(cid)
                if target is not None:
                    target.append(data[pos:end] if collect_records else log_time)
                elif cid not in channels:
                    raise _err(self.path, f"corrupted chunk at byte {where}: message on undefined channel {cid}")
            elif opcode == Opcode.SCHEMA:
                schema = _record(Schema, data[pos + 9:end])
                self.scan.schemas[schema.id] = schema
            elif opcode == Opcode.CHANNEL:
                channel = _record(Channel, data[pos + 9:end])
                if channel.id not in channels:
                    self._add_channel(self.scan, channel, where)
                    if on_channel is not None:
                        on_channel(channel.id)
            elif opcode not in _KNOWN_OPCODES and opcode < 0x80:
                raise _err(self.path, f"corrupted chunk at byte {where}: invalid record opcode 0x{opcode:02x}")
            pos = end


# -- summary -----------------------------------------------------------------------------------

def log_summary(path: str | Path) -> dict[str, Any]:
    """Channels (topic, encodings, schema, count, first/last time, rate), message count,
    time span, metadata and attachments of a log; for an unfinished file ``complete`` is
    False and ``truncated_at``/``note`` say where and why the readable part ends."""
    with _File(path) as f:
        scan = f.scan
        times: dict[int, array] = {cid: array("q") for cid in scan.channels}
        f.walk(times, collect_records=False,
               on_channel=lambda cid: times.setdefault(cid, array("q")))
        start = scan.start_ns()
        channels = []
        end = None
        for cid, info in scan.channels.items():
            ch, schema = info.channel, info.schema
            t = times.get(cid, array("q"))
            first = min(t) if t else None
            last = max(t) if t else None
            if last is not None:
                end = last if end is None else max(end, last)
            span = (last - first) / 1e9 if t else 0.0
            channels.append({
                "id": ch.id, "topic": ch.topic, "message_encoding": ch.message_encoding,
                "schema_name": schema.name if schema else "",
                "schema_encoding": schema.encoding if schema else "",
                "count": len(t),
                "first_s": (first - start) / 1e9 if t else None,
                "last_s": (last - start) / 1e9 if t else None,
                "rate_hz": (len(t) - 1) / span if len(t) > 1 and span > 0 else None,
                "field_names": _schema_fields(f.path, ch.message_encoding, schema),
            })
        return {
            "path": str(scan.path),
            "size_bytes": scan.size,
            "complete": scan.complete,
            "truncated_at": scan.truncated_at,
            "note": scan.note,
            "library": scan.header.library if scan.header else "",
            "profile": scan.header.profile if scan.header else "",
            "start_ns": start,
            "end_ns": end,
            "duration_s": (end - start) / 1e9 if start is not None and end is not None else 0.0,
            "message_count": sum(c["count"] for c in channels),
            "chunk_count": sum(1 for r in scan.data_records if r[4]),
            "compression": sorted(scan.compressions),
            "channels": channels,
            "metadata": {m.name: dict(m.metadata) for m in scan.metadata},
            "attachments": [{"name": n, "media_type": t, "size_bytes": s} for n, t, s in scan.attachments],
        }


def _schema_fields(path: Path, encoding: str, schema: Schema | None) -> list[str]:
    """The columns read_log gives a channel, from its schema alone: a protobuf message's
    fields, a JSON Schema's properties (nested objects as ``a.b``, as _flatten does); [] for
    anything else."""
    if schema is None or not schema.data:
        return []
    if encoding == "protobuf" and schema.encoding == "protobuf":
        try:
            fds = descriptor_pb2.FileDescriptorSet.FromString(schema.data)
        except Exception as exc:
            raise _err(path, f"schema {schema.name!r} is not a valid protobuf FileDescriptorSet ({exc})") from None
        package, _, short = schema.name.rpartition(".")
        for file in fds.file:
            for msg in file.message_type:
                if file.package == package and msg.name == short:
                    return [fd.name for fd in msg.field]
        return []
    if encoding == "json" and schema.encoding == "jsonschema":
        try:
            return _json_properties(json.loads(schema.data))
        except ValueError:
            raise _err(path, f"schema {schema.name!r} is not valid JSON") from None
    return []


def _json_properties(node: Any, prefix: str = "") -> list[str]:
    props = node.get("properties") if isinstance(node, dict) else None
    if not isinstance(props, dict):
        return [prefix] if prefix else []
    out: list[str] = []
    for key, sub in props.items():
        name = f"{prefix}.{key}" if prefix else str(key)
        nested = sub.get("properties") if isinstance(sub, dict) else None
        out += _json_properties(sub, name) if nested else [name]
    return out


def read_attachment(path: str | Path, name: str) -> bytes:
    """The data of the first attachment called `name`."""
    with _File(path) as f:
        pos = 8
        buf = f.buf
        limit = f.scan.truncated_at or len(buf)
        while pos + 9 <= limit:
            opcode, length = _HEAD.unpack_from(buf, pos)
            if opcode == Opcode.ATTACHMENT:
                att = _record(Attachment, buf[pos + 9:pos + 9 + length])
                if att.name == name:
                    return att.data
            if opcode in (Opcode.DATA_END, Opcode.FOOTER):
                break
            pos += 9 + length
    raise KeyError(f"{path}: no attachment named {name!r}")


# -- reading messages into columns ---------------------------------------------------------------

def read_log(path: str | Path, topics: Iterable[str] | None = None,
             t0: float | None = None, t1: float | None = None) -> LogData:
    """Messages of `topics` (default all) with log time in [t0, t1] seconds from the log's
    first message, as columns per topic (:class:`TopicData`). Reads unfinished files up to
    their last finished chunk (see ``LogData.complete``/``truncated_at``)."""
    with _File(path) as f:
        scan = f.scan
        wanted = None if topics is None else ({topics} if isinstance(topics, str) else set(topics))
        start = scan.start_ns()
        window = None
        if start is not None and (t0 is not None or t1 is not None):
            lo = start + int(round(t0 * 1e9)) if t0 is not None else 0
            hi = start + int(round(t1 * 1e9)) if t1 is not None else 2**64 - 1
            if hi < lo:
                raise ValueError(f"time window t0={t0} s > t1={t1} s")
            window = (lo, hi)
        records: dict[int, list[bytes]] = {}

        def want(cid: int) -> None:
            if wanted is None or f.scan.channels[cid].channel.topic in wanted:
                records.setdefault(cid, [])

        for cid in scan.channels:
            want(cid)
        f.walk(records, collect_records=True, window=window, on_channel=want)
        if wanted is not None:
            known = {info.channel.topic for info in scan.channels.values()}
            missing = sorted(wanted - known)
            if missing:
                raise KeyError(f"{f.path}: no topic {', '.join(missing)}; "
                               f"topics: {', '.join(sorted(known)) or '(none)'}")
        out = LogData(f.path, scan.complete, scan.truncated_at, scan.note, start)
        for cid, recs in records.items():
            info = scan.channels[cid]
            data = _decode(f.path, info, recs, start or 0)
            if window is not None:
                keep = (data.log_time_ns >= window[0]) & (data.log_time_ns <= window[1])
                if not keep.all():
                    data = TopicData(data.topic, data.message_encoding, data.schema_name,
                                     data.log_time_ns[keep], data.t_s[keep],
                                     {k: v[keep] for k, v in data.fields.items()})
            out[info.channel.topic] = data
        return out


def _decode(path: Path, info: _ChannelInfo, recs: list[bytes], start_ns: int) -> TopicData:
    channel, schema = info.channel, info.schema
    encoding = channel.message_encoding
    fields: dict[str, np.ndarray] | None = None
    log_time: np.ndarray | None = None
    if encoding == "protobuf" and schema is not None and schema.encoding == "protobuf":
        layout = _fixed_layout(path, schema)
        if layout is not None:
            decoded = _decode_fixed(layout, recs)
            if decoded is not None:
                log_time, fields = decoded
        if fields is None:
            log_time, rows = _times_and_rows(recs, _protobuf_decoder(path, schema))
            fields = _columns(rows)
    elif encoding == "json":
        log_time, rows = _times_and_rows(recs, lambda payload: _flatten(json.loads(payload)))
        fields = _columns(rows)
    else:  # an encoding we do not decode: give the raw payloads
        log_time, rows = _times_and_rows(recs, lambda payload: {"data": payload})
        fields = _columns(rows)
    return TopicData(channel.topic, encoding, schema.name if schema else "", log_time,
                     (log_time.astype(np.int64) - start_ns) / 1e9, fields)


def _fixed_layout(path: Path, schema: Schema) -> tuple[np.dtype, dict[str, int], list[str]] | None:
    """numpy dtype of a whole Message record of a fixed-layout protobuf message, with the
    expected tag of each field; None if the message has any other kind of field."""
    try:
        fds = descriptor_pb2.FileDescriptorSet.FromString(schema.data)
    except Exception as exc:
        raise _err(path, f"schema {schema.name!r} is not a valid protobuf FileDescriptorSet ({exc})") from None
    package, _, short = schema.name.rpartition(".")
    for file in fds.file:
        if file.package != package:
            continue
        for msg in file.message_type:
            if msg.name != short:
                continue
            spec = [("_op", "u1"), ("_len", "<u8"), ("_cid", "<u2"), ("_seq", "<u4"),
                    ("_log_time", "<u8"), ("_publish_time", "<u8")]
            tags: dict[str, int] = {}
            names = []
            for fd in msg.field:
                if fd.label == _F.LABEL_REPEATED or fd.type not in _FIXED_DTYPES:
                    return None
                dtype, wire = _FIXED_DTYPES[fd.type]
                tag = (fd.number << 3) | wire
                tag_bytes = 1 if tag < 0x80 else 2 if tag < 0x4000 else 0
                if not tag_bytes:
                    return None
                encoded = tag if tag_bytes == 1 else ((tag & 0x7F) | 0x80) | ((tag >> 7) << 8)
                spec.append((f"_tag_{fd.name}", "u1" if tag_bytes == 1 else "<u2"))
                spec.append((fd.name, dtype))
                tags[f"_tag_{fd.name}"] = encoded
                names.append(fd.name)
            return np.dtype(spec), tags, names
    raise _err(path, f"schema {schema.name!r}: its FileDescriptorSet does not define that message")


def _decode_fixed(layout, recs: list[bytes]):
    dtype, tags, names = layout
    if recs and set(map(len, recs)) != {dtype.itemsize}:
        return None
    arr = np.frombuffer(b"".join(recs), dtype=dtype)
    for tag_field, expected in tags.items():
        if not (arr[tag_field] == expected).all():
            return None
    return (arr["_log_time"].astype(np.int64),
            {name: arr[name].astype(arr[name].dtype.newbyteorder("=")) for name in names})


def _protobuf_decoder(path: Path, schema: Schema):
    pool = descriptor_pool.DescriptorPool()
    fds = descriptor_pb2.FileDescriptorSet.FromString(schema.data)
    for file in fds.file:
        pool.Add(file)
    try:
        cls = message_factory.GetMessageClass(pool.FindMessageTypeByName(schema.name))
    except KeyError:
        raise _err(path, f"schema {schema.name!r}: its FileDescriptorSet does not define that message") from None
    scalar = [fd.name for fd in cls.DESCRIPTOR.fields
              if fd.type != fd.TYPE_MESSAGE and not fd.is_repeated]

    def decode(payload: bytes) -> dict[str, Any]:
        msg = cls.FromString(payload)
        row = _flatten(json_format.MessageToDict(msg, preserving_proto_field_name=True))
        for name in scalar:  # keeps bytes as bytes and 64-bit integers as integers
            row[name] = getattr(msg, name)
        return row

    return decode


def _times_and_rows(recs: list[bytes], decode) -> tuple[np.ndarray, list[dict[str, Any]]]:
    times = np.fromiter((_MSG.unpack_from(r)[4] for r in recs), dtype=np.int64, count=len(recs))
    return times, [decode(r[_MSG_PREFIX_LEN:]) for r in recs]


def _flatten(obj: Any, prefix: str = "") -> dict[str, Any]:
    if not isinstance(obj, dict):
        return {prefix or "value": obj}
    out: dict[str, Any] = {}
    for key, value in obj.items():
        name = f"{prefix}.{key}" if prefix else str(key)
        if isinstance(value, dict) and value:
            out.update(_flatten(value, name))
        else:
            out[name] = value
    return out


def _columns(rows: list[dict[str, Any]]) -> dict[str, np.ndarray]:
    keys: dict[str, None] = {}
    for row in rows:
        for key in row:
            keys.setdefault(key, None)
    cols = {}
    for key in keys:
        values = [row.get(key) for row in rows]
        present = [v for v in values if v is not None]
        if present and all(isinstance(v, bool) for v in present) and len(present) == len(values):
            cols[key] = np.array(values, dtype=bool)
        elif present and all(isinstance(v, int) and not isinstance(v, bool) for v in present) \
                and len(present) == len(values) and all(-2**63 <= v < 2**63 for v in present):
            cols[key] = np.array(values, dtype=np.int64)
        elif present and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in present):
            cols[key] = np.array([np.nan if v is None else float(v) for v in values], dtype=np.float64)
        else:
            col = np.empty(len(values), dtype=object)
            col[:] = values
            cols[key] = col
    return cols
