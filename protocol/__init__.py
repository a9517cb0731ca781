"""The hil-bench wire protocol (protocol/SPEC.md).

messages      message dataclasses and constants, mirroring protocol/c/hil_proto.h
codec         serial framing: payloads, FrameEncoder, StreamDecoder
can_mapping   CAN identifiers, packing, segmentation and reassembly
links         serial / CAN / in-process links with one interface (open_link, make_pair)
vector_file, vector_cases   the shared test vectors read by the Python and C tests
"""
