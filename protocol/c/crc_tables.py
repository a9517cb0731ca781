"""Prints hil_proto.c's crc_slice tables (CRC-16/CCITT-FALSE, slicing-by-4), from the polynomial.

    python3 protocol/c/crc_tables.py

crc_slice[0][i]: the register after shifting byte i in, MSB first, polynomial 0x1021, bit by
bit. crc_slice[k][i]: byte i followed by k zero bytes, (crc_slice[k-1][i] << 8) ^
crc_slice[0][crc_slice[k-1][i] >> 8]. tests/test_protocol_ccodec.py checks that hil_proto.c
holds exactly these lines.
"""
from __future__ import annotations

POLY = 0x1021
SLICES = 4


def tables() -> list[list[int]]:
    first = []
    for i in range(256):
        reg = i << 8
        for _ in range(8):
            reg = ((reg << 1) ^ POLY if reg & 0x8000 else reg << 1) & 0xFFFF
        first.append(reg)
    out = [first]
    for _ in range(1, SLICES):
        prev = out[-1]
        out.append([((v << 8) & 0xFFFF) ^ first[v >> 8] for v in prev])
    return out


def c_lines() -> list[str]:
    lines = [f"static const uint16_t crc_slice[{SLICES}][256] = {{"]
    for table in tables():
        lines.append("    {")
        for row in range(0, 256, 8):
            lines.append("        " + " ".join(f"0x{v:04X}u," for v in table[row:row + 8]))
        lines.append("    },")
    lines.append("};")
    return lines


if __name__ == "__main__":
    print("\n".join(c_lines()))
