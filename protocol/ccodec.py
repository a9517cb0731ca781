"""The firmware's C codec (protocol/c/hil_proto.c) as the bench's serial codec.

Same API as protocol/codec.py for framing: ``FrameEncoder``, ``StreamDecoder`` (with the
same counters, ``last_seq``, ``last_bad_version``, ``buffered``, ``reset``) and
``encode_frame``; messages are protocol/messages.py's own classes, so a message decoded here
equals the one the Python codec decodes. The payload-level helpers (encode_payload,
decode_payload, ...) are the Python codec's, re-exported.

The work is done by the extension module protocol/c/build/_hilcodec*.so (``make -C
protocol/c ext``, run by scripts/bootstrap.sh): one call per ``feed`` decodes every frame of
the chunk with hil_decoder_feed_buf and builds the message objects in C. A message the C
encoder cannot take as it is (a field of the wrong type or out of range) goes to the Python
codec, which encodes it the same way or raises the ProtocolError naming the field.

This module always imports; when the extension is not built ``AVAILABLE`` is False,
``UNAVAILABLE_REASON`` says why, and taking any codec name from it raises ImportError with that
reason. ``protocol.codec_impl()`` picks this codec when it is available.
Environment: HIL_CCODEC_PATH loads the extension from another file (the sanitizer build).
"""
from __future__ import annotations

import importlib.machinery
import importlib.util
import os
from pathlib import Path

from protocol import codec as _pycodec
from protocol.codec import (  # noqa: F401 - re-exported: the API of protocol.codec
    COUNTER_NAMES, CRC_SIZE, HEADER_SIZE, HELLO_FIXED_SIZE, MAX_ENCODED_FRAME, MAX_ENCODED_SEGMENT,
    MAX_PAYLOAD, MAX_RAW_FRAME, PAYLOAD_SIZES, ProtocolError, decode_payload, encode_payload, pack_adc40,
)
from protocol.messages import MESSAGE_CLASSES

BUILD_DIR = Path(__file__).resolve().parent / "c" / "build"
_API = ("FrameEncoder", "StreamDecoder", "encode_frame", "crc16", "exchange_sample",
        "exchange_periods", "records_into", "stage_period", "stage_telemetry", "index_span",
        "chunk_tail")


def extension_path() -> Path:
    """Where the extension is looked for (HIL_CCODEC_PATH, else protocol/c/build/)."""
    override = os.environ.get("HIL_CCODEC_PATH")
    if override:
        return Path(override).resolve()
    return BUILD_DIR / f"_hilcodec{importlib.machinery.EXTENSION_SUFFIXES[0]}"


def _load():
    path = extension_path()
    if not path.is_file():
        raise ImportError(f"the C codec extension {path} is not built: run make -C protocol/c ext "
                          f"(or make bootstrap)")
    loader = importlib.machinery.ExtensionFileLoader("protocol._hilcodec", str(path))
    spec = importlib.util.spec_from_file_location("protocol._hilcodec", str(path), loader=loader)
    module = importlib.util.module_from_spec(spec)
    loader.exec_module(module)
    # The C side writes the message classes' slots directly and encodes what it cannot take
    # through the Python codec.
    module.setup({int(t): cls for t, cls in MESSAGE_CLASSES.items()}, _pycodec.encode_frame)
    if (module.MAX_ENCODED_SEGMENT, module.PROTOCOL_VERSION) != (MAX_ENCODED_SEGMENT, _pycodec.PROTOCOL_VERSION):
        raise ImportError(f"{path} was built from another protocol version; run make -C protocol/c ext")
    return module


try:
    _ext = _load()
except (ImportError, OSError, TypeError) as exc:
    _ext = None
    AVAILABLE = False
    UNAVAILABLE_REASON = str(exc)
else:
    AVAILABLE = True
    UNAVAILABLE_REASON = ""
    FrameEncoder = _ext.FrameEncoder
    StreamDecoder = _ext.StreamDecoder
    encode_frame = _ext.encode_frame
    crc16 = _ext.crc16
    exchange_sample = _ext.exchange_sample
    # a build older than the period loop has none: the bench's loop then runs every period
    exchange_periods = getattr(_ext, "exchange_periods", None)
    records_into = getattr(_ext, "records_into", None)
    stage_period = getattr(_ext, "stage_period", None)
    stage_telemetry = getattr(_ext, "stage_telemetry", None)
    index_span = getattr(_ext, "index_span", None)
    chunk_tail = getattr(_ext, "chunk_tail", None)


def __getattr__(name: str):
    if name in _API:
        raise ImportError(f"protocol.ccodec.{name}: {UNAVAILABLE_REASON}")
    raise AttributeError(f"module 'protocol.ccodec' has no attribute {name!r}")
