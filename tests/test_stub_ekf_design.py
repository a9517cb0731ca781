"""EKF gain design (hil/design/ekf.py): DLQE by the discrete Riccati equation, and
the gains the stub ships with equal the design for the documented covariances."""
from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from hil.design.ekf import EkfNoiseModel, default_gains, design_gains, transition_matrix
from hil.links.stub_library import StubLibraryLink
from protocol.messages import ParamGet, ParamId, ParamValue

REPO = Path(__file__).resolve().parent.parent
DEFAULTS_H = REPO / "firmware_stub" / "core" / "defaults.h"
T = 50e-6


def _riccati_iteration(t, r, q, steps=200000):
    """The time-varying Kalman filter's Riccati difference equation, iterated to its fixed
    point from P = I: the steady-state gain without scipy."""
    f = transition_matrix(t)
    h = np.array([[1.0, 0.0, 0.0]])
    qm = np.diag([0.0, 0.0, q])
    p = np.eye(3)
    for _ in range(steps):
        s = (h @ p @ h.T).item() + r
        m = p @ h.T / s
        p_next = f @ (p - m @ h @ p) @ f.T + qm
        if np.allclose(p_next, p, rtol=1e-13, atol=0):
            break
        p = p_next
    m = p @ h.T / ((h @ p @ h.T).item() + r)
    return (f @ m).ravel()


def test_gains_are_the_riccati_fixed_point():
    r, q = 0.0136**2, 0.00625**2
    g = design_gains(T, r, q)
    k_iter = _riccati_iteration(T, r, q)
    np.testing.assert_allclose([g.k1, g.k2_rad_s, g.k3_rad_s], k_iter, rtol=1e-6)


def test_estimator_is_stable_and_faster_with_more_process_noise():
    r = 0.0136**2
    bands = []
    for q in (1e-6, 1e-5, 1e-4, 1e-3):
        g = design_gains(T, r, q)
        f = transition_matrix(T)
        closed = f - np.outer([g.k1, g.k2_rad_s, g.k3_rad_s], [1.0, 0.0, 0.0])
        assert np.max(np.abs(np.linalg.eigvals(closed))) < 1.0
        assert g.k1 > 0 and g.k2_rad_s > 0 and g.k3_rad_s > 0
        bands.append(max(g.poles_rad_s))
    assert bands == sorted(bands) and bands[-1] > 2 * bands[0]


def test_noise_model_against_the_closed_loop():
    """The angle noise the gains are designed for, sigma_v, against the flux-angle jitter the
    stub's estimator actually shows in the loop (not the formula restated): at constant speed
    the per-period increments of the estimated flux angle scatter by sqrt(2) sigma_v for white
    noise. The model is a uniform-step approximation: agreement within a factor 1.5."""
    from hil.run.runner import Bench

    m = EkfNoiseModel()
    with Bench(link="stub") as bench:
        bench.param_set("telemetry_divider", 1)
        bench.command(enable=True, speed_source="encoder", speed_ref_rpm=1500)
        bench.run(0.3)
        t_end = bench.plant.t_s
        angle = bench.signals()["ctrl.flux_angle_rad"].window(t_end - 0.04, t_end)
    steps = np.diff(np.unwrap(angle.values))
    sigma_measured = float(np.std(steps)) / np.sqrt(2.0)
    assert m.angle_std_rad() / 1.5 <= sigma_measured <= m.angle_std_rad() * 1.5, \
        (sigma_measured, m.angle_std_rad())


def test_bad_covariances_rejected():
    with pytest.raises(ValueError, match="positive"):
        design_gains(T, -1.0, 1e-5)
    with pytest.raises(ValueError, match="positive"):
        design_gains(0.0, 1e-4, 1e-5)


def _defaults_h() -> dict[str, float]:
    text = DEFAULTS_H.read_text()
    return {name: float(value) for name, value in
            re.findall(r"#define (CTL_DEFAULT_EKF_K\w+) ([-0-9.eE+]+)f", text)}


def test_shipped_defaults_equal_design_in_float32():
    g = default_gains()
    want = np.float32([g.k1, g.k2_rad_s, g.k3_rad_s])
    # as written in the source
    h = _defaults_h()
    got_h = np.float32([h["CTL_DEFAULT_EKF_K1"], h["CTL_DEFAULT_EKF_K2_RAD_S"], h["CTL_DEFAULT_EKF_K3_RAD_S"]])
    np.testing.assert_array_equal(got_h, want)
    # as the firmware reports them over the protocol
    link = StubLibraryLink()
    got = []
    for pid in (ParamId.EKF_K1, ParamId.EKF_K2, ParamId.EKF_K3):
        link.send(ParamGet(int(pid)))
        answer = link.recv()
        assert isinstance(answer, ParamValue) and answer.status == 0
        got.append(answer.value)
    link.close()
    np.testing.assert_array_equal(np.float32(got), want)


def test_cli_prints_the_c_defines():
    out = subprocess.run([sys.executable, "-m", "hil.design.ekf"], cwd=REPO, capture_output=True,
                         text=True, check=True).stdout
    printed = {name: float(value) for name, value in re.findall(r"#define (\w+) ([-0-9.eE+]+)f", out)}
    assert printed == pytest.approx(_defaults_h(), rel=1e-8)
