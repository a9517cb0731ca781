"""The hil-bench wire protocol (protocol/SPEC.md).

messages      message dataclasses and constants, mirroring protocol/c/hil_proto.h
codec         serial framing: payloads, FrameEncoder, StreamDecoder (pure Python, the reference)
ccodec        the same framing API through the firmware's C codec (extension module)
codec_impl()  the one the bench uses: C when built, else Python (HIL_CODEC=python|c forces)
can_mapping   CAN identifiers, packing, segmentation and reassembly
links         serial / CAN / in-process links with one interface (open_link, make_pair)
vector_file, vector_cases   the shared test vectors read by the Python and C tests
"""

import os as _os

CODEC_ENV = "HIL_CODEC"


def codec_impl():
    """The serial codec the bench uses: protocol.ccodec (the firmware's C codec as an extension
    module) when it is built, protocol.codec (pure Python, the reference) otherwise. Both have the
    same API (FrameEncoder, StreamDecoder, encode_frame, COUNTER_NAMES, ProtocolError, ...).

    HIL_CODEC=python or HIL_CODEC=c forces one; with c, a missing extension is an ImportError that
    says how to build it. Which one it is: the module's __name__.
    """
    choice = _os.environ.get(CODEC_ENV, "").strip().lower()
    if choice not in ("", "auto", "c", "python"):
        raise ValueError(f"{CODEC_ENV}={choice!r}: expected python, c or auto")
    if choice == "python":
        from protocol import codec
        return codec
    from protocol import ccodec
    if ccodec.AVAILABLE:
        return ccodec
    if choice == "c":
        raise ImportError(f"{CODEC_ENV}=c: {ccodec.UNAVAILABLE_REASON}")
    from protocol import codec
    return codec
