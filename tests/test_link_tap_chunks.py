"""However a link cuts the board's byte stream into reads (whole frames, a frame split across
reads, a read that ends inside the next frame, one byte at a time), the tap hands the session
the same messages in the same order and captures the same bytes and frame count."""
from __future__ import annotations

import random

from hil.session.link_tap import LinkTap
from protocol.codec import FrameEncoder
from protocol.messages import Gates, Telemetry


class _Reads:
    """A byte link whose reads return the given chunks, one per call, then nothing."""

    url = "reads"
    counters: dict[str, int] = {}

    def __init__(self, chunks: list[bytes]):
        self.chunks = list(chunks)

    def read_bytes(self, timeout_s=None) -> bytes:
        return self.chunks.pop(0) if self.chunks else b""

    def send_bytes(self, data: bytes) -> None:
        pass


def _stream() -> tuple[bytes, list]:
    enc = FrameEncoder()
    msgs = []
    for k in range(40):
        msgs += [Telemetry(k, k % 6, 2, 1, 0x21, *[0.5 * k + i for i in range(12)]), Gates(k, 0x21)]
    return b"".join(enc.encode(m) for m in msgs), msgs


def _through_tap(chunks: list[bytes]) -> tuple[list, bytes, int]:
    tap = LinkTap(_Reads(chunks))
    got = []
    for _ in range(len(chunks) + 100):
        msg = tap.recv(0.0)
        if msg is not None:
            got.append(msg)
    capture = tap.take_capture()["in"]
    return got, capture[0], capture[1]


def test_any_cut_of_the_stream_gives_the_same_messages_and_capture():
    data, msgs = _stream()
    frames = data.split(b"\x00")[:-1]
    whole = [f + b"\x00" for f in frames]
    pairs = [whole[i] + whole[i + 1] for i in range(0, len(whole), 2)]
    rng = random.Random(5)
    cuts = sorted(rng.sample(range(1, len(data)), 60))
    ragged = [data[a:b] for a, b in zip([0] + cuts, cuts + [len(data)])]
    bytewise = [data[i:i + 1] for i in range(len(data))]
    for chunks in (whole, pairs, ragged, bytewise, [data]):
        got, captured, count = _through_tap(chunks)
        assert got == msgs
        assert captured == data and count == len(msgs)
