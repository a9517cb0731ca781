"""The MCAP records the run log writes, serialized by hand as the MCAP specification lays
them out (https://mcap.dev/spec, "Records"): an opcode byte, the body's length as a uint64,
then the body's fields, little-endian; a string or a byte array is its uint32 length and its
bytes, a map is its uint32 length in bytes and its key-value pairs.

The mcap package's record classes write the same bytes, but importing them builds 16
dataclasses, ~40 M instructions of every `hil run`'s start; the reader (hil.logs.reader)
still uses the package. tests/test_mcap_records.py holds every function here to the
package's writer, record by record and for whole files.
"""
from __future__ import annotations

import struct
import zlib
from collections.abc import Mapping

MAGIC = b"\x89MCAP0\r\n"

# Opcodes (the values of mcap.opcode.Opcode)
HEADER = 0x01
FOOTER = 0x02
SCHEMA = 0x03
CHANNEL = 0x04
MESSAGE = 0x05
CHUNK = 0x06
MESSAGE_INDEX = 0x07
CHUNK_INDEX = 0x08
ATTACHMENT = 0x09
ATTACHMENT_INDEX = 0x0A
STATISTICS = 0x0B
METADATA = 0x0C
METADATA_INDEX = 0x0D
SUMMARY_OFFSET = 0x0E
DATA_END = 0x0F

HEAD = struct.Struct("<BQ")          # opcode, body length: the 9 bytes before every body
_U32 = struct.Struct("<I")


def record(opcode: int, body: bytes) -> bytes:
    return HEAD.pack(opcode, len(body)) + body


def _string(text: str) -> bytes:
    data = text.encode()
    return _U32.pack(len(data)) + data


def _bytes(data: bytes) -> bytes:
    return _U32.pack(len(data)) + data


def _map(mapping: Mapping[str, str]) -> bytes:
    body = b"".join(_string(k) + _string(v) for k, v in mapping.items())
    return _U32.pack(len(body)) + body


def _id_map(mapping: Mapping[int, int]) -> bytes:
    """A map of uint16 ids to uint64 values (channel ids to offsets or counts)."""
    body = b"".join(struct.pack("<HQ", k, v) for k, v in mapping.items())
    return _U32.pack(len(body)) + body


def header(profile: str, library: str) -> bytes:
    return record(HEADER, _string(profile) + _string(library))


def schema(schema_id: int, name: str, encoding: str, data: bytes) -> bytes:
    return record(SCHEMA, struct.pack("<H", schema_id) + _string(name) + _string(encoding) + _bytes(data))


def channel(channel_id: int, schema_id: int, topic: str, message_encoding: str,
            metadata: Mapping[str, str]) -> bytes:
    return record(CHANNEL, struct.pack("<HH", channel_id, schema_id) + _string(topic)
                  + _string(message_encoding) + _map(metadata))


def metadata(name: str, mapping: Mapping[str, str]) -> bytes:
    return record(METADATA, _string(name) + _map(mapping))


def metadata_index(offset: int, length: int, name: str) -> bytes:
    return record(METADATA_INDEX, struct.pack("<QQ", offset, length) + _string(name))


def attachment(log_time: int, create_time: int, name: str, media_type: str, data: bytes) -> bytes:
    """The CRC at its end is the CRC-32 of the body before it."""
    body = (struct.pack("<QQ", log_time, create_time) + _string(name) + _string(media_type)
            + struct.pack("<Q", len(data)) + data)
    return record(ATTACHMENT, body + _U32.pack(zlib.crc32(body)))


def attachment_index(offset: int, length: int, log_time: int, create_time: int, data_size: int,
                     name: str, media_type: str) -> bytes:
    return record(ATTACHMENT_INDEX, struct.pack("<QQQQQ", offset, length, log_time, create_time, data_size)
                  + _string(name) + _string(media_type))


def chunk_index(message_start_time: int, message_end_time: int, chunk_start_offset: int,
                chunk_length: int, message_index_offsets: Mapping[int, int], message_index_length: int,
                compression: str, compressed_size: int, uncompressed_size: int) -> bytes:
    return record(CHUNK_INDEX, struct.pack("<QQQQ", message_start_time, message_end_time,
                                           chunk_start_offset, chunk_length)
                  + _id_map(message_index_offsets) + struct.pack("<Q", message_index_length)
                  + _string(compression) + struct.pack("<QQ", compressed_size, uncompressed_size))


def statistics(message_count: int, schema_count: int, channel_count: int, attachment_count: int,
               metadata_count: int, chunk_count: int, message_start_time: int, message_end_time: int,
               channel_message_counts: Mapping[int, int]) -> bytes:
    return record(STATISTICS, struct.pack("<QHIIIIQQ", message_count, schema_count, channel_count,
                                          attachment_count, metadata_count, chunk_count,
                                          message_start_time, message_end_time)
                  + _id_map(channel_message_counts))


def data_end(data_section_crc: int) -> bytes:
    return record(DATA_END, _U32.pack(data_section_crc))


def summary_offset(group_opcode: int, group_start: int, group_length: int) -> bytes:
    return record(SUMMARY_OFFSET, struct.pack("<BQQ", group_opcode, group_start, group_length))

