"""MCAP run log: protobuf channels packed by hand for the full-rate data, JSON for the rare.

Why not ``mcap.writer.Writer.add_message``: it builds a dataclass and a dozen small
struct.pack calls per message (about 4 us for 20 doubles, bench/mcap_logging.py). Here a
full-rate message is one precompiled ``struct.Struct.pack_into`` of the whole MCAP
Message record, protobuf payload included, into the preallocated open chunk (about
1.4 us); the chunk's message indexes, the metadata, the summary and the footer are
serialized by hil.logs.mcap_records (the bytes of the mcap package's record classes, without
importing them). Files read back with the mcap package's readers (CRCs validated) and open
in Foxglove.

Protobuf wire format used (only fixed-width scalar fields, none omitted, so the layout
of every message of a channel is constant): each field is its tag varint
(``field_number << 3 | wire_type``, one byte up to field 15, two bytes up to 2047)
followed by the little-endian value (wire type 1 = 8 bytes, 5 = 4 bytes).

Crash safety: each finished chunk is handed to the kernel with one write() before the
next message is accepted, so a SIGKILL loses at most the open chunk (see
docs/logging.md); an unclosed file is read by :mod:`hil.logs.reader`. Not thread-safe:
one thread (the session's) writes.
"""
from __future__ import annotations

import json
import math
import os
import struct
import sys
import zlib
from array import array
from collections.abc import Mapping
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

from hil.logs import mcap_records as rec
from protocol import ccodec

LIBRARY = "hil-bench mcap_log"
DEFAULT_CHUNK_SIZE = 64 * 1024
MAX_CHUNK_SIZE = 64 * 1024 * 1024

# protobuf scalar type name -> (FieldDescriptorProto type, wire type, struct code). The types
# are descriptor.proto's FieldDescriptorProto.Type numbers (TYPE_DOUBLE = 1, ...; a test holds
# them to google.protobuf's): the schemas are serialized here without importing descriptor_pb2,
# ~0.03 s of every run's start.
FIXED_TYPES: dict[str, tuple[int, int, str]] = {
    "double": (1, 1, "d"),      # TYPE_DOUBLE
    "float": (2, 5, "f"),       # TYPE_FLOAT
    "fixed32": (7, 5, "I"),     # TYPE_FIXED32
    "sfixed32": (15, 5, "i"),   # TYPE_SFIXED32
    "fixed64": (6, 1, "Q"),     # TYPE_FIXED64
    "sfixed64": (16, 1, "q"),   # TYPE_SFIXED64
}
_TYPE_BYTES = 12                # FieldDescriptorProto.TYPE_BYTES
_LABEL_OPTIONAL = 1             # FieldDescriptorProto.LABEL_OPTIONAL

#: The C codec extension's record packer (FixedChannel.write_many), None without it.
_RECORDS_INTO = ccodec.records_into if ccodec.AVAILABLE else None
#: The chunk's time span from its message indexes in one C call (protocol.ccodec.index_span),
#: where numpy's took two reductions a channel, about 45 us a chunk; None: numpy's.
_INDEX_SPAN = ccodec.index_span if ccodec.AVAILABLE else None
#: The records after a chunk (its MessageIndexes and its ChunkIndex) in one C call
#: (protocol.ccodec.chunk_tail), where Python built them a channel at a time; None: Python's
#: (_chunk_tail below, the reference: the same bytes).
_CHUNK_TAIL = ccodec.chunk_tail if ccodec.AVAILABLE else None

# Message record prefix: opcode, record length, channel id, sequence, log time, publish time.
_MESSAGE_PREFIX = "<BQHIQQ"
_MESSAGE_PREFIX_LEN = struct.calcsize(_MESSAGE_PREFIX)  # 31 bytes, of which 22 are the body
_MESSAGE_PREFIX_STRUCT = struct.Struct(_MESSAGE_PREFIX)
_BYTES_COUNT_TAG = (1 << 3) | 5  # field 1 `count`, fixed32
_BYTES_DATA_TAG = (2 << 3) | 2  # field 2 `data`, length-delimited
_BYTES_HEAD = struct.Struct("<BIB")  # count tag, count, data tag (its length varint follows)


def tag_varint(field_number: int, wire_type: int) -> bytes:
    """Protobuf tag as a varint; constant per field, so it is packed once per message layout."""
    value = (field_number << 3) | wire_type
    return _varint(value)


def _varint(value: int) -> bytes:
    out = bytearray()
    while True:
        byte = value & 0x7F
        value >>= 7
        if value:
            out.append(byte | 0x80)
        else:
            out.append(byte)
            return bytes(out)


def _split_name(message_name: str) -> tuple[str, str]:
    package, _, short = message_name.rpartition(".")
    if not short.isidentifier() or (package and not all(p.isidentifier() for p in package.split("."))):
        raise ValueError(f"protobuf message name {message_name!r} is not a dotted identifier")
    return package, short


def _len_field(number: int, data: bytes) -> bytes:
    """A length-delimited protobuf field (a string or an embedded message)."""
    return tag_varint(number, 2) + _varint(len(data)) + data


def _descriptor_set(message_name: str, fields: list[tuple[str, int]]) -> bytes:
    """Serialized FileDescriptorSet of one proto3 message whose fields are (name, type number),
    numbered 1..n: the bytes google.protobuf's SerializeToString gives (fields in number order,
    every set field written, an empty package too; tests/test_mcap_log.py compares them)."""
    package, short = _split_name(message_name)
    message = _len_field(1, short.encode())                                 # DescriptorProto.name
    for number, (name, type_number) in enumerate(fields, start=1):
        message += _len_field(2, (_len_field(1, name.encode())             # .field: name,
                                  + tag_varint(3, 0) + _varint(number)     # number,
                                  + tag_varint(4, 0) + _varint(_LABEL_OPTIONAL)  # label,
                                  + tag_varint(5, 0) + _varint(type_number)))    # type
    file = (_len_field(1, (message_name.replace(".", "/") + ".proto").encode())  # name
            + _len_field(2, package.encode())                               # package
            + _len_field(4, message)                                        # message_type
            + _len_field(12, b"proto3"))                                    # syntax
    return _len_field(1, file)                                              # FileDescriptorSet.file


def fixed_descriptor_set(message_name: str, fields: list[tuple[str, str]]) -> bytes:
    """Serialized FileDescriptorSet of one proto3 message of fixed-width scalar fields.

    Field numbers are 1..n in the order given; this order is also the wire order.
    """
    return _descriptor_set(message_name, [(name, FIXED_TYPES[type_name][0])
                                          for name, type_name in fields])


def bytes_descriptor_set(message_name: str) -> bytes:
    """FileDescriptorSet of a batch message: `fixed32 count = 1; bytes data = 2;`."""
    return _descriptor_set(message_name, [("count", FIXED_TYPES["fixed32"][0]),
                                          ("data", _TYPE_BYTES)])


def json_schema_of(obj: Any) -> dict:
    """A JSON Schema describing `obj`'s shape, loose enough for the topic's later messages:
    properties are not required, every number is "number" (a 0 now may be 0.5 later) and
    a null says nothing about the type."""
    if isinstance(obj, bool):
        return {"type": "boolean"}
    if isinstance(obj, (int, float)):
        return {"type": "number"}
    if isinstance(obj, str):
        return {"type": "string"}
    if obj is None:
        return {}
    if isinstance(obj, Mapping):
        return {"type": "object", "properties": {str(k): json_schema_of(v) for k, v in obj.items()}}
    if isinstance(obj, (list, tuple)):
        return {"type": "array", "items": json_schema_of(obj[0]) if obj else {}}
    if hasattr(obj, "item") or hasattr(obj, "tolist"):  # numpy scalar or array
        return json_schema_of(_json_default(obj))
    return {}


def _json_default(obj: Any) -> Any:
    if hasattr(obj, "tolist"):  # numpy scalars and arrays
        return obj.tolist()
    if isinstance(obj, (bytes, bytearray)):
        return obj.hex()
    if isinstance(obj, Path):
        return str(obj)
    raise TypeError(f"{type(obj).__name__} is not JSON serializable")


def _finite(obj: Any) -> Any:
    """JSON has no NaN or infinity: Foxglove and json parsers reject them, so they become null."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, Mapping):
        return {k: _finite(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_finite(v) for v in obj]
    if hasattr(obj, "tolist"):
        return _finite(obj.tolist())
    return obj


def _string_map(name: str, data: Mapping[str, Any]) -> dict[str, str]:
    """MCAP metadata is string to string: scalars become str, structures JSON."""
    if not isinstance(data, Mapping):
        raise TypeError(f"metadata {name!r} must be a mapping of names to values, not {type(data).__name__}")
    out = {}
    for key, value in data.items():
        if isinstance(value, str):
            out[str(key)] = value
        elif isinstance(value, (Mapping, list, tuple)):
            out[str(key)] = json.dumps(_finite(value), default=_json_default, sort_keys=True)
        else:
            out[str(key)] = str(value)
    return out


class _OpenChunk:
    """The chunk being filled: a preallocated buffer and its fill level, shared by all
    channels. Records are packed into it in place (no per-message bytes object, no
    regrowth after each chunk)."""

    __slots__ = ("buf", "fill", "limit")

    def __init__(self, limit: int):
        self.limit = limit
        self.buf = bytearray(limit + _FIXED_RECORD_MAX)
        self.fill = 0


_FIXED_RECORD_MAX = 64 * 1024


def _new_index() -> array:
    """A channel's entries in the open chunk's MessageIndex: log time and offset, interleaved
    as unsigned 64-bit integers, the record's own layout, so one tobytes() writes them (a list
    of (time, offset) tuples cost a struct.pack argument per integer)."""
    return array("Q")


def _little_endian(index: array) -> bytes:
    if sys.byteorder == "big":
        index = array("Q", index)
        index.byteswap()
    return index.tobytes()


class FixedChannel:
    """A protobuf channel whose every message has the same fixed-width layout."""

    __slots__ = ("topic", "message_name", "field_names", "channel_id", "record_size", "_log", "_args",
                 "_pack_into", "_chunk", "_index", "_dtype", "_template", "_value_names", "_int_cols",
                 "_int_lo", "_int_hi", "_field_types", "_layout")

    def __init__(self, log: McapLog, channel_id: int, topic: str, message_name: str,
                 fields: list[tuple[str, str]]):
        self._log = log
        self.topic = topic
        self.message_name = message_name
        self.channel_id = channel_id
        self.field_names = tuple(name for name, _ in fields)
        self._field_types = tuple(type_name for _, type_name in fields)
        self._layout = None        # (template bytes, struct codes, value offsets): _packed
        fmt = _MESSAGE_PREFIX
        payload = 0
        tail: list[int | float] = []
        for number, (_, type_name) in enumerate(fields, start=1):
            _, wire, code = FIXED_TYPES[type_name]
            tag = tag_varint(number, wire)
            fmt += ("B" if len(tag) == 1 else "H") + code
            tail += [int.from_bytes(tag, "little"), 0]
            payload += len(tag) + struct.calcsize("<" + code)
        self.record_size = _MESSAGE_PREFIX_LEN + payload
        if self.record_size > _FIXED_RECORD_MAX:
            raise ValueError(f"{topic}: {len(fields)} fields make a {self.record_size}-byte message; "
                             f"at most {_FIXED_RECORD_MAX} bytes")
        self._pack_into = struct.Struct(fmt).pack_into
        self._chunk = log._open
        # pack_into(buffer, offset, opcode, length, channel, sequence, log time, publish time, tag, value, ...)
        self._args = [self._chunk.buf, 0, rec.MESSAGE, self.record_size - 9, channel_id, 0, 0, 0] + tail
        self._index = _new_index()
        # The same record as a numpy structured type, for write_many: a batch of messages is
        # filled column by column and copied into the chunk in one go.
        names, formats, offsets = ["op", "length", "channel", "seq", "log_time", "publish_time"], \
            ["u1", "<u8", "<u2", "<u4", "<u8", "<u8"], [0, 1, 9, 11, 15, 23]
        pos = _MESSAGE_PREFIX_LEN
        numpy_codes = {"d": "<f8", "f": "<f4", "I": "<u4", "i": "<i4", "Q": "<u8", "q": "<i8"}
        for number, (_, type_name) in enumerate(fields, start=1):
            _, wire, code = FIXED_TYPES[type_name]
            tag = tag_varint(number, wire)
            names += [f"t{number}", f"v{number}"]
            formats += ["u1" if len(tag) == 1 else "<u2", numpy_codes[code]]
            offsets += [pos, pos + len(tag)]
            pos += len(tag) + struct.calcsize("<" + code)
        self._dtype = np.dtype({"names": names, "formats": formats, "offsets": offsets,
                                "itemsize": self.record_size})
        # Integer fields are checked as one block per batch (whole, finite, in range): one
        # pass of a few ufuncs instead of six reductions per column.
        self._value_names = [f"v{i + 1}" for i in range(len(fields))]
        self._int_cols = [i for i, name in enumerate(self._value_names)
                          if self._dtype[name].kind in "ui"]
        self._int_lo = np.array([np.iinfo(self._dtype[self._value_names[i]]).min for i in self._int_cols],
                                dtype=np.float64)
        self._int_hi = np.array([np.iinfo(self._dtype[self._value_names[i]]).max for i in self._int_cols],
                                dtype=np.float64)
        self._template = np.zeros(1, self._dtype)
        self._template["op"] = rec.MESSAGE
        self._template["length"] = self.record_size - 9
        self._template["channel"] = channel_id
        for number, (_, type_name) in enumerate(fields, start=1):
            self._template[f"t{number}"] = int.from_bytes(
                tag_varint(number, FIXED_TYPES[type_name][1]), "little")

    def write_many(self, log_times_ns, values) -> None:
        """Log len(log_times_ns) messages at once: `values` is a 2-D array (one row per
        message, columns in the declared field order). The records are packed in one C call
        (protocol.ccodec.records_into: straight into the open chunk when the batch fits it,
        else staged and copied) or, without it or for a value it does not take, built column by
        column with numpy, so a message costs tens of nanoseconds instead of a Python call; the
        chunk is finished whenever it fills, as with write()."""
        times = np.asarray(log_times_ns, dtype=np.uint64)
        n = times.shape[0]
        if n == 0:
            return
        values = np.asarray(values)
        if values.ndim != 2 or values.shape != (n, len(self.field_names)):
            raise ValueError(f"{self.topic}: expected {n} rows of {len(self.field_names)} values "
                             f"({', '.join(self.field_names)}), got shape {values.shape}")
        if _RECORDS_INTO is not None and values.dtype == np.float64:
            chunk = self._chunk
            pos = chunk.fill
            size = self.record_size
            if n <= max(1, -(-(chunk.limit - pos) // size)) and self._packed_into(
                    chunk.buf, pos, times, values):
                # the whole batch fitted the open chunk (write()'s rule: it may end on or one
                # record past the limit) and went straight into it, with no staging copy
                end = pos + n * size
                self._index_pairs(times, pos, end)
                chunk.fill = end
                if end >= chunk.limit:
                    self._log._finish_chunk()
                return
        raw = self._packed(times, values) if _RECORDS_INTO is not None else None
        if raw is None:
            records = np.repeat(self._template, n)
            records["log_time"] = times
            records["publish_time"] = times
            with np.errstate(invalid="raise", over="raise"):
                try:
                    if self._int_cols and values.dtype.kind == "f":
                        self._check_whole(values[:, self._int_cols])
                    for i, name in enumerate(self._value_names):
                        records[name] = values[:, i]
                except (ValueError, FloatingPointError, TypeError) as exc:
                    raise ValueError(f"{self.topic}: a value does not fit its field type ({exc})") from None
            raw = records.view(np.uint8).reshape(-1)
        size = self.record_size
        done = 0
        log = self._log
        while done < n:
            chunk = self._chunk
            pos = chunk.fill
            # as many records as take the chunk to its limit (write() stops at the first
            # record that reaches it); the buffer has room for one record past the limit
            fit = max(1, -(-(chunk.limit - pos) // size))
            take = min(fit, n - done)
            end = pos + take * size
            with memoryview(chunk.buf) as view:
                view[pos:end] = raw[done * size:(done + take) * size]
            self._index_pairs(times[done:done + take], pos, end)
            chunk.fill = end
            done += take
            if end >= chunk.limit:
                log._finish_chunk()

    def _index_pairs(self, times: np.ndarray, pos: int, end: int) -> None:
        """The message index's (log time, offset) pairs of the records from `pos` to `end`."""
        pairs = np.empty((len(times), 2), dtype=np.uint64)
        pairs[:, 0] = times
        pairs[:, 1] = np.arange(pos, end, self.record_size, dtype=np.uint64)
        self._index.frombytes(pairs.tobytes())

    def _record_layout(self) -> tuple[bytes, bytes, tuple[int, ...]]:
        """records_into's description of a record: template bytes, struct codes, offsets."""
        layout = self._layout
        if layout is None:
            template = self._template.tobytes()
            codes = "".join(FIXED_TYPES[t][2] for t in self._field_types).encode()
            offsets = tuple(self._dtype.fields[name][1] for name in self._value_names)
            layout = self._layout = (template, codes, offsets)
        return layout

    def _packed_into(self, out, pos: int, times: np.ndarray, values: np.ndarray) -> bool:
        """The float64 rows packed by records_into into `out` from byte `pos`; False, with
        `out` untouched, when a value does not fit its field (the numpy path then names it)."""
        try:
            _RECORDS_INTO(out, pos, *self._record_layout(), times, np.ascontiguousarray(values))
        except ValueError:
            return False
        return True

    def _packed(self, times: np.ndarray, values: np.ndarray) -> np.ndarray | None:
        """The records as bytes, built in one C call (protocol.ccodec.records_into: faster than
        numpy's column by column in sessions side by side, bench mcap_logging's
        records_into_in_session, and ~450 fewer instructions a logged period in the recorder's
        seal, bench.period_instructions; numpy's strided column copies cost memory traffic
        more than instructions); None for values that are
        not float64 or that do not all fit their fields (the numpy path then decides, and names
        the value and the field)."""
        if values.dtype != np.float64:
            return None
        raw = np.empty(len(times) * self.record_size, dtype=np.uint8)
        return raw if self._packed_into(raw, 0, times, values) else None

    def _check_whole(self, block: np.ndarray) -> None:
        """The integer fields' values (as floats): whole, finite and in their types' ranges."""
        with np.errstate(invalid="ignore"):
            ok = (block == np.floor(block)) & (block >= self._int_lo) & (block <= self._int_hi)
        if ok.all():
            return
        row, col = np.argwhere(~ok)[0]
        value, field = float(block[row, col]), self._int_cols[col]
        if not np.isfinite(value) or value != np.floor(value):
            raise ValueError(f"'{self.field_names[field]}' = {value!r}: a whole number is expected")
        raise ValueError(f"'{self.field_names[field]}' = {value!r}: outside "
                         f"{int(self._int_lo[col])}..{int(self._int_hi[col])}")

    def write(self, log_time_ns: int, *values: float | int) -> None:
        """Log one message; `values` in the declared field order."""
        chunk = self._chunk
        pos = chunk.fill
        args = self._args
        args[1] = pos
        args[6] = args[7] = log_time_ns
        try:
            args[9::2] = values
            self._pack_into(*args)
        except (ValueError, struct.error, TypeError) as exc:
            raise ValueError(self._bad_values(values, exc)) from None
        end = pos + self.record_size
        chunk.fill = end
        index = self._index
        index.append(log_time_ns)
        index.append(pos)
        if end >= chunk.limit:
            self._log._finish_chunk()

    def _bad_values(self, values: tuple, exc: Exception) -> str:
        if len(values) != len(self.field_names):
            return (f"{self.topic}: expected {len(self.field_names)} values "
                    f"({', '.join(self.field_names)}), got {len(values)}")
        return f"{self.topic}: a value does not fit its field type ({exc}); values {values!r}"


class _VariableChannel:
    __slots__ = ("topic", "channel_id", "_log", "_chunk", "_index")

    def __init__(self, log: McapLog, channel_id: int, topic: str):
        self._log = log
        self.topic = topic
        self.channel_id = channel_id
        self._chunk = log._open
        self._index = _new_index()

    def _append(self, log_time_ns: int, payload, head: bytes = b"") -> None:
        """One message of `head` then `payload` (any bytes-like object: copied once, into
        the chunk)."""
        chunk = self._chunk
        pos = chunk.fill
        end = pos + _MESSAGE_PREFIX_LEN + len(head) + len(payload)
        prefix = _MESSAGE_PREFIX_STRUCT.pack(
            rec.MESSAGE, end - pos - 9, self.channel_id, 0, log_time_ns, log_time_ns) + head
        mid = pos + len(prefix)
        # slice assignment writes in place, growing the buffer only for an outsized message
        buf = chunk.buf
        buf[pos:mid] = prefix
        buf[mid:end] = payload
        chunk.fill = end
        index = self._index
        index.append(log_time_ns)
        index.append(pos)
        if end >= chunk.limit:
            self._log._finish_chunk()


class BytesChannel(_VariableChannel):
    """A protobuf channel of batches: `count` items (e.g. raw frames) concatenated in `data`."""

    __slots__ = ("message_name",)

    def __init__(self, log: McapLog, channel_id: int, topic: str, message_name: str):
        super().__init__(log, channel_id, topic)
        self.message_name = message_name

    def write(self, log_time_ns: int, data: bytes, count: int) -> None:
        try:
            head = _BYTES_HEAD.pack(_BYTES_COUNT_TAG, count, _BYTES_DATA_TAG)
        except struct.error:
            raise ValueError(f"{self.topic}: count {count!r} is not a 32-bit unsigned integer") from None
        self._append(log_time_ns, data, head + _varint(len(data)))


class JsonChannel(_VariableChannel):
    __slots__ = ("schema_name",)

    def __init__(self, log: McapLog, channel_id: int, topic: str, schema_name: str):
        super().__init__(log, channel_id, topic)
        self.schema_name = schema_name

    def write(self, log_time_ns: int, obj: Mapping[str, Any]) -> None:
        try:
            text = json.dumps(obj, separators=(",", ":"), allow_nan=False, default=_json_default)
        except ValueError:
            text = json.dumps(_finite(obj), separators=(",", ":"), allow_nan=False, default=_json_default)
        self._append(log_time_ns, text.encode())


#: From this many bytes on (the chunks, not the small records around them) the log's CRC-32s
#: go to ISA-L's (the isal package), which uses the CPU's carry-less multiply: a 64 KiB chunk
#: in ~5 us against ~23 us for zlib 1.2.13's here, where the two CRCs of the data were 2,864
#: of a logged period's ~46,000 instructions (bench.period_instructions). Below it zlib's is as
#: quick and costs no import, so a short run does not pay one.
_ISAL_CRC_FROM = 16 * 1024
_isal_crc32 = None


def crc32(data: bytes | bytearray | memoryview, value: int = 0) -> int:
    """MCAP's CRC-32 (zlib's) of `data`, continuing from `value` (a CRC of what came before)."""
    global _isal_crc32
    if len(data) < _ISAL_CRC_FROM:
        return zlib.crc32(data, value)
    if _isal_crc32 is None:
        from isal.isal_zlib import crc32 as _isal_crc32
    return _isal_crc32(data, value)


#: lz4 frame compression level of the log's chunks: -3 is LZ4's fast mode with acceleration
#: 4 (lz4frame.c: -level + 1; the library's default, 0, is acceleration 1). On this bench's
#: chunks it compresses as well as 0 and -2 in fewer instructions (bench.mcap_logging prints
#: the file sizes of all three, bench.period_instructions the instructions of a logged
#: period: about 600 fewer than at -2); from -4 on the files grow.
LZ4_LEVEL = -3

#: the chunk compressions McapLog writes (MCAP's names; "none" is written as "")
COMPRESSIONS = ("lz4", "zstd", "none")


def _chunk_tail(active: list, chunk_start: int, chunk_length: int, start: int, end: int,
                compression: str, compressed_size: int, uncompressed_size: int) -> tuple[bytes, bytes]:
    """The MessageIndex records of a chunk's `active` channels, written right after it, and
    its ChunkIndex record: protocol.ccodec.chunk_tail's reference."""
    parts = []
    offsets = {}
    index_pos = chunk_start + chunk_length
    for c in active:
        idx = c._index
        n = len(idx) // 2
        offsets[c.channel_id] = index_pos
        record = (rec.HEAD.pack(rec.MESSAGE_INDEX, 6 + 16 * n)
                  + struct.pack("<HI", c.channel_id, 16 * n) + _little_endian(idx))
        parts.append(record)
        index_pos += len(record)
    chunk_index = rec.chunk_index(start, end, chunk_start, chunk_length, offsets,
                                  index_pos - chunk_start - chunk_length, compression,
                                  compressed_size, uncompressed_size)
    return b"".join(parts), chunk_index


class McapLog:
    """Writer of one run's MCAP file.

    ``compression``: "lz4" (default: nearly free; at ``lz4_level``, None: LZ4_LEVEL), "zstd"
    (level ``zstd_level``: smaller files, about 0.5 us a period more) or "none".
    ``chunk_size``: the open chunk is compressed and written once it holds this many
    bytes; a SIGKILL loses at most that much uncompressed data.
    """

    def __init__(self, path: str | os.PathLike, metadata: Mapping[str, Mapping[str, Any]] | None = None,
                 chunk_size: int = DEFAULT_CHUNK_SIZE, compression: str = "lz4", zstd_level: int = 1,
                 lz4_level: int | None = None):
        self.path = Path(path)
        if not 1024 <= chunk_size <= MAX_CHUNK_SIZE:
            raise ValueError(f"chunk_size {chunk_size}: use 1 KiB to {MAX_CHUNK_SIZE >> 20} MiB "
                             f"(the open chunk is preallocated)")
        self.chunk_size = int(chunk_size)
        self.compression = compression
        if compression == "zstd":
            import zstandard
            self._compress = zstandard.ZstdCompressor(level=zstd_level).compress
        elif compression == "lz4":
            import lz4.frame
            self._compress = partial(lz4.frame.compress,
                                     compression_level=LZ4_LEVEL if lz4_level is None else lz4_level)
        elif compression in ("none", ""):
            self.compression = ""
            self._compress = None
        else:
            raise ValueError(f"compression {compression!r}: use 'zstd', 'lz4' or 'none'")
        self._open = _OpenChunk(self.chunk_size)
        self._channels: list[FixedChannel | BytesChannel | JsonChannel] = []
        self._by_topic: dict[str, FixedChannel | BytesChannel | JsonChannel] = {}
        # The summary's records, serialized (hil.logs.mcap_records); schema ids by content
        self._schemas: dict[tuple[str, str, bytes], int] = {}
        self._schema_records: list[bytes] = []
        self._channel_records: list[bytes] = []
        self._chunk_indexes: list[bytes] = []
        self._metadata_indexes: list[bytes] = []
        self._attachment_indexes: list[bytes] = []
        self._message_counts: dict[int, int] = {}
        self._time_range: tuple[int, int] | None = None
        self._metadata_count = 0
        self._closed = False
        self._failed = False
        # Writers that batch messages (hil.logs.recorder) hand their pending batch over here
        # before the open chunk is flushed or the file is finished.
        self._before_flush: list = []
        self._pos = 0
        self._crc = 0
        try:
            self._file = open(self.path, "wb", buffering=0)
        except OSError as exc:
            raise type(exc)(exc.errno, f"cannot create MCAP log: {exc.strerror}", str(self.path)) from None
        try:
            self._write(rec.MAGIC + rec.header("", LIBRARY))
            for name, data in (metadata or {}).items():
                self.add_metadata(name, data)
        except BaseException:
            self._release()
            raise

    # -- channels -------------------------------------------------------------------------
    def add_fixed_channel(self, topic: str, message_name: str, fields: list[tuple[str, str]]) -> FixedChannel:
        """A full-rate protobuf channel; ``fields`` are (name, type) with type in FIXED_TYPES."""
        fields = [(str(n), str(t)) for n, t in fields]
        if not fields:
            raise ValueError(f"{topic}: a fixed channel needs at least one field")
        for name, type_name in fields:
            if type_name not in FIXED_TYPES:
                raise ValueError(f"{topic}: field {name!r} has type {type_name!r}; "
                                 f"fixed-width types are {', '.join(FIXED_TYPES)}")
            if not name.isidentifier():
                raise ValueError(f"{topic}: field name {name!r} is not an identifier")
        names = [n for n, _ in fields]
        if len(set(names)) != len(names):
            raise ValueError(f"{topic}: duplicate field names in {names}")
        schema_id = self._schema(message_name, "protobuf", fixed_descriptor_set(message_name, fields))
        channel_id = self._channel(topic, "protobuf", schema_id)
        return self._register(FixedChannel(self, channel_id, topic, message_name, fields))

    def add_bytes_channel(self, topic: str, message_name: str) -> BytesChannel:
        """A protobuf channel of batches of raw bytes (e.g. one message per N periods of frames)."""
        schema_id = self._schema(message_name, "protobuf", bytes_descriptor_set(message_name))
        channel_id = self._channel(topic, "protobuf", schema_id)
        return self._register(BytesChannel(self, channel_id, topic, message_name))

    def add_json_channel(self, topic: str, schema: Mapping[str, Any] | None = None,
                         schema_name: str | None = None) -> JsonChannel:
        """A JSON channel for rare messages; ``schema`` is a JSON Schema (default: any object)."""
        schema = dict(schema) if schema is not None else {"type": "object"}
        name = schema_name or "hil" + topic.replace("/", ".")
        schema_id = self._schema(name, "jsonschema", json.dumps(schema, sort_keys=True).encode())
        channel_id = self._channel(topic, "json", schema_id)
        return self._register(JsonChannel(self, channel_id, topic, name))

    def write_json(self, topic: str, log_time_ns: int, obj: Mapping[str, Any]) -> None:
        """Log a JSON message; the topic's channel and schema are made on first use from `obj`."""
        channel = self._by_topic.get(topic)
        if channel is None:
            channel = self.add_json_channel(topic, json_schema_of(obj))
        elif not isinstance(channel, JsonChannel):
            raise ValueError(f"{topic} is a protobuf channel; write_json needs a JSON topic")
        channel.write(log_time_ns, obj)

    def channel(self, topic: str) -> FixedChannel | BytesChannel | JsonChannel:
        return self._by_topic[topic]

    # -- metadata and attachments -----------------------------------------------------------
    def add_metadata(self, name: str, data: Mapping[str, Any]) -> None:
        self._check_open()
        record = rec.metadata(str(name), _string_map(name, data))
        self._metadata_indexes.append(rec.metadata_index(self._pos, len(record), str(name)))
        self._metadata_count += 1
        self._write(record)

    def add_attachment(self, name: str, data: bytes, media_type: str = "application/octet-stream",
                       log_time_ns: int = 0) -> None:
        self._check_open()
        record = rec.attachment(log_time_ns, 0, str(name), media_type, bytes(data))
        self._attachment_indexes.append(rec.attachment_index(
            self._pos, len(record), log_time_ns, 0, len(data), str(name), media_type))
        self._write(record)

    # -- life cycle --------------------------------------------------------------------------
    def before_flush(self, callback) -> None:
        """`callback()` runs before every flush() and close(): a batching writer empties its
        batch into the log there."""
        self._before_flush.append(callback)

    def flush(self) -> None:
        """Write the open chunk now, so that everything logged so far survives a crash."""
        self._check_open()
        for callback in self._before_flush:
            callback()
        self._finish_chunk()

    def close(self) -> None:
        """Finish the file (chunk, indexes, summary, footer). Idempotent. After a failed
        write it only releases the file, so it never hides the first error."""
        if self._closed:
            return
        try:
            if not self._failed:
                for callback in self._before_flush:
                    callback()
        finally:
            self._closed = True
        try:
            if not self._failed:
                self._finish_chunk()
                self._write_summary()
        finally:
            self._release()

    def __enter__(self) -> McapLog:
        return self

    def __exit__(self, *exc_info) -> None:
        self.close()

    def __del__(self):
        if not getattr(self, "_closed", True):
            self._release()

    @property
    def closed(self) -> bool:
        return self._closed

    # -- internals -----------------------------------------------------------------------------
    def _release(self) -> None:
        self._closed = True
        self._open.limit = -1  # a write after this reaches _finish_chunk, which raises
        file = getattr(self, "_file", None)
        if file is not None and not file.closed:
            file.close()

    def _check_open(self) -> None:
        if self._closed:
            raise ValueError(f"MCAP log {self.path} is closed")
        if self._failed:
            raise OSError(f"MCAP log {self.path} failed earlier; nothing more is written")

    def _write(self, data: bytes | bytearray | memoryview) -> None:
        try:
            view = memoryview(data)
            while view:
                n = self._file.write(view)
                view = view[n:]
        except OSError as exc:
            self._failed = True
            self._open.limit = -1
            raise type(exc)(exc.errno, f"cannot write MCAP log: {exc.strerror}", str(self.path)) from None
        self._crc = crc32(data, self._crc)
        self._pos += len(data)

    def _schema(self, name: str, encoding: str, data: bytes) -> int:
        key = (name, encoding, data)
        schema_id = self._schemas.get(key)
        if schema_id is None:
            self._check_open()
            schema_id = len(self._schemas) + 1
            record = rec.schema(schema_id, name, encoding, data)
            self._write(record)
            self._schemas[key] = schema_id
            self._schema_records.append(record)
        return schema_id

    def _channel(self, topic: str, message_encoding: str, schema_id: int) -> int:
        self._check_open()
        if topic in self._by_topic:
            raise ValueError(f"{self.path}: topic {topic} already has a channel")
        channel_id = len(self._channel_records) + 1
        record = rec.channel(channel_id, schema_id, topic, message_encoding, {})
        self._write(record)
        self._channel_records.append(record)
        return channel_id

    def _register(self, channel):
        self._channels.append(channel)
        self._by_topic[channel.topic] = channel
        return channel

    def _finish_chunk(self) -> None:
        """Compress the open chunk and write it with one message index per channel."""
        if self._failed:
            raise OSError(f"MCAP log {self.path} failed earlier; nothing more is written")
        if self._file.closed:
            raise ValueError(f"MCAP log {self.path} is closed")
        chunk = self._open
        fill = chunk.fill
        if not fill:
            return
        active = [c for c in self._channels if c._index]
        if _INDEX_SPAN is not None:
            start, end = _INDEX_SPAN([c._index for c in active])
        else:
            times = [np.frombuffer(c._index, dtype=np.uint64)[0::2] for c in active]
            start = int(min(t.min() for t in times))
            end = int(max(t.max() for t in times))
        with memoryview(chunk.buf) as whole, whole[:fill] as raw:
            data = self._compress(raw) if self._compress else bytes(raw)
            raw_crc = crc32(raw)
        compression = self.compression.encode()
        body_head = struct.pack(f"<QQQII{len(compression)}sQ", start, end, fill, raw_crc,
                                len(compression), compression, len(data))
        chunk_record = rec.HEAD.pack(rec.CHUNK, len(body_head) + len(data)) + body_head
        chunk_start = self._pos
        chunk_length = len(chunk_record) + len(data)
        tail = (chunk_start, chunk_length, start, end, self.compression, len(data), fill)
        if _CHUNK_TAIL is not None:
            indexes, chunk_index = _CHUNK_TAIL([c.channel_id for c in active],
                                               [c._index for c in active], *tail)
        else:
            indexes, chunk_index = _chunk_tail(active, *tail)
        counts = self._message_counts
        for c in active:
            counts[c.channel_id] = counts.get(c.channel_id, 0) + len(c._index) // 2
            c._index = _new_index()
        chunk.fill = 0
        self._write(b"".join((chunk_record, data, indexes)))
        self._chunk_indexes.append(chunk_index)
        if self._time_range is None:
            self._time_range = (start, end)
        else:
            self._time_range = (min(start, self._time_range[0]), max(end, self._time_range[1]))

    def _write_summary(self) -> None:
        self._write(rec.data_end(self._crc))       # the CRC of the data section up to here
        summary_start = self._pos
        parts: list[bytes] = []
        offsets: list[bytes] = []
        size = 0

        def group(opcode: int, records: list[bytes]) -> None:
            nonlocal size
            begin = size
            for record in records:
                parts.append(record)
                size += len(record)
            if size > begin:
                offsets.append(rec.summary_offset(opcode, summary_start + begin, size - begin))

        start, end = self._time_range or (0, 0)
        stats = rec.statistics(
            sum(self._message_counts.values()), len(self._schemas), len(self._channel_records),
            len(self._attachment_indexes), self._metadata_count, len(self._chunk_indexes),
            start, end, self._message_counts)
        group(rec.SCHEMA, self._schema_records)
        group(rec.CHANNEL, self._channel_records)
        group(rec.STATISTICS, [stats])
        group(rec.CHUNK_INDEX, self._chunk_indexes)
        group(rec.ATTACHMENT_INDEX, self._attachment_indexes)
        group(rec.METADATA_INDEX, self._metadata_indexes)
        summary_offset_start = summary_start + size
        summary = b"".join(parts + offsets)
        footer_head = struct.pack("<BQQQ", rec.FOOTER, 20, summary_start, summary_offset_start)
        summary_crc = crc32(footer_head, crc32(summary))
        self._write(summary + footer_head + struct.pack("<I", summary_crc) + rec.MAGIC)
