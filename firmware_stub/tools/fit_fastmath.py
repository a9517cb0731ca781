"""Regenerates the polynomial coefficients of firmware_stub/core/fastmath.[ch].

Near-minimax fits by Lawson's iteration (iteratively reweighted least squares on
a dense grid), rounded to float32; prints each set with its maximum error in
double precision. The error bounds including float rounding are asserted by
firmware_stub/tests/test_fastmath.c.

    .venv/bin/python firmware_stub/tools/fit_fastmath.py
"""
from __future__ import annotations

import numpy as np


def lawson(columns: np.ndarray, target: np.ndarray, iterations: int = 300) -> np.ndarray:
    """Coefficients c minimising max |columns @ c - target| (approximately)."""
    w = np.full(len(target), 1.0 / len(target))
    c = np.zeros(columns.shape[1])
    for _ in range(iterations):
        sw = np.sqrt(w)
        c, *_ = np.linalg.lstsq(columns * sw[:, None], target * sw, rcond=None)
        err = np.abs(columns @ c - target)
        w = w * err
        w /= w.sum()
    return np.float32(c).astype(float)


def report(name: str, coefficients: np.ndarray, columns: np.ndarray, target: np.ndarray) -> None:
    err = np.max(np.abs(columns @ coefficients - target))
    print(f"{name}: max error {err:.3g}")
    for k, c in enumerate(coefficients):
        print(f"  {k}: {float(c)!r}f")


def main() -> None:
    # sin(r) = r + r^3 (S1 + r^2 (S2 + r^2 S3)), |r| <= pi/4 (fused sincos)
    r = np.linspace(-np.pi / 4, np.pi / 4, 40001)
    cols = np.stack([r**3, r**5, r**7], 1)
    report("FM_S1..S3", lawson(cols, np.sin(r) - r), cols, np.sin(r) - r)
    # cos(r) = 1 + r^2 (C1 + r^2 (C2 + r^2 C3)), |r| <= pi/4
    cols = np.stack([r**2, r**4, r**6], 1)
    report("FM_C1..C3", lawson(cols, np.cos(r) - 1), cols, np.cos(r) - 1)
    # sin(r) = r + r^3 (W1 + r^2 (W2 + r^2 W3)), |r| <= pi/2 (fm_sin)
    r = np.linspace(-np.pi / 2, np.pi / 2, 40001)
    cols = np.stack([r**3, r**5, r**7], 1)
    report("FM_W1..W3", lawson(cols, np.sin(r) - r), cols, np.sin(r) - r)
    # atan(z) = z (A0 + z^2 (A1 + ... + z^2 A5)), 0 <= z <= 1
    z = np.linspace(0, 1, 40001)
    cols = np.stack([z ** (2 * k + 1) for k in range(6)], 1)
    report("FM_A0..A5", lawson(cols, np.arctan(z)), cols, np.arctan(z))
    # asin(x) = pi/2 - sqrt(1 - x) (B0 + x (B1 + ... + x B5)), 0 <= x <= 1
    x = np.linspace(0, 1, 200001)
    cols = np.stack([x**k for k in range(6)], 1) * np.sqrt(1 - x)[:, None]
    target = np.pi / 2 - np.arcsin(x)
    report("FM_B0..B5", lawson(cols, target), cols, target)


if __name__ == "__main__":
    main()
