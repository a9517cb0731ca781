"""The stub's start-up stator-resistance identification (RS_ID_PERIODS, docs/stub.md) in a
session on the paper-hardware profile: the stub in process, every protocol byte, the plant
with its warm winding, inverter and transducer errors.

What R the board must find, and how well (derived before this test first ran; the plant runs
of docs/stub.md, seeds 0-7 giving 0.5646 .. 0.5666 ohm, were known when it was written):

- Expected value. The board computes its duties from its DC-link reading, 1.008 v + 0.6 V
  (LV25-P gain and offset), (1 + e_v) v with e_v = 0.6 / 70 + 0.008 = 0.016571 at 70 V, and
  reads its current g = 1.005 high (LA25-NP). Two levels give
  R_id = (1 + e_v) R / g = 1.016571 x 0.5592 / 1.005 = 0.56564 ohm.
- Errors with no bias: the current offset (calibrated to 0.05 count at start-up, and an offset
  cancels in I2 - I1 anyway); the inverter's dead time and drop (a constant voltage at a fixed
  current sign, cancelled by the two points: the plant's drop is flat above its 0.1 A knee and
  phases b, c carry -1 A at the low level); the ADC's 1-count quantisation (dithered by its
  1 count rms of noise); the DC-link reading's noise (1 count = 24 mV, 3.5e-4 of the reading,
  enters the duties and averages to 1e-7 of R); the loop's settling (1.3 ms slowest pole,
  < 1e-6 A left after the 12.5 ms settling quarter).
- Spread, from the current noise sigma_n = 1 count = 12.2 mA (i_d = i_alpha = i_a at the
  encoder's zero angle): the means of M = 750 samples a level, R sigma_n sqrt(2 / M) / dI =
  0.5592 x 12.2e-3 x 0.0516 / 2 = 0.18 mOhm; the loop's noise in the true current,
  sigma_i = sigma_n sqrt(pi f_c / f_s) = 12.2 mA x sqrt(pi 500 / 20000) = 3.4 mA, through the
  window's L di/dt term, 2 L sigma_i / (W dI) = 2 x 4.8e-3 x 3.4e-3 / (0.0375 x 2) = 0.44 mOhm.
  Together sigma_R = 0.47 mOhm.
- Bound: 5 sigma_R = 2.4 mOhm, rounded to 2.5: |R_id - 0.56564| < 2.5 mOhm. That also tells
  the board's scales from the winding's own 0.5592 (6.4 mOhm lower, 13 sigma) and from the cold
  0.466 it started with.
- The rotor stays put: the d current is aligned on the magnet and makes no torque; only the
  noise in i_q does, 1.5 p psi_f sigma_iq = 1.5 x 0.0928 x 12.2 mA = 1.7 mNm rms. Even held
  constant at 2 mNm for the 101 ms on 8e-4 kg m^2 it would turn the rotor by
  (T / J) t^2 / 2 = 2.5 x 0.101^2 / 2 = 0.0128 rad = 0.73 deg: the bound.
"""
from __future__ import annotations

import math
import subprocess
from pathlib import Path

import numpy as np
import pytest

from hil.links.stub_library import STUB_DIR
from hil.session.bench_session import BenchSession, SessionConfig
from hil.session.board_params import board_parameters, default_board, load_bench_profile
from plant_rt import TRUTH_FIELDS
from protocol.messages import ParamGet, ParamId

HARDWARE = Path(__file__).resolve().parent.parent / "plant_rt" / "profiles" / "paper-hardware.yaml"
R_ID_EXPECTED = (1.008 + 0.6 / 70.0) * 0.5592 / 1.005
BOUND_OHM = 2.5e-3


@pytest.fixture(scope="module", autouse=True)
def built() -> None:
    subprocess.run(["make", "-s", "-C", str(STUB_DIR)], check=True, capture_output=True)


def _read(session: BenchSession, pid: ParamId) -> float:
    answer = session._param_exchange(ParamGet(id=int(pid)), int(pid), f"{pid.name} (PARAM_GET)")
    assert answer.status == 0
    return answer.value


def test_identified_resistance_on_paper_hardware():
    profile = load_bench_profile(HARDWARE)
    told = {s.name: s.value for s in board_parameters(profile, default_board("stub"),
                                                       "paper-hardware")}
    n_level = int(told["rs_id_periods"])
    assert n_level == 1000 and int(told["current_zero_cal_periods"]) == 400
    f = {name: i for i, name in enumerate(TRUTH_FIELDS)}
    with BenchSession(profile, SessionConfig(link="stub", seed=0, hold_cpu_latency=False)) as s:
        assert _read(s, ParamId.STATOR_RESISTANCE_OHM) == pytest.approx(0.466, abs=1e-6)
        s.send_command(enable=True, speed_source="encoder", speed_ref_rpm=1500)
        startup = 400 + 2 * n_level + 20          # zero calibration, two levels, bridge open
        s.run_periods(startup)
        s.drain()
        r_id = _read(s, ParamId.STATOR_RESISTANCE_OHM)
        truth = np.asarray(s.recorder.truth_rows)
        # the drive starts after it: 1500 rpm reached
        s.run_periods(int(0.3 / 50e-6))
        s.drain()
        final_rpm = np.asarray(s.recorder.truth_rows)[-1, f["speed_rpm"]]
    assert abs(r_id - R_ID_EXPECTED) < BOUND_OHM, (r_id, R_ID_EXPECTED)
    assert r_id - 0.5592 > 6.4e-3 - BOUND_OHM          # through the board's scales
    assert math.degrees(np.max(np.abs(truth[:, f["theta_m_rad"]]))) < 0.73
    # the current levels were driven along d (alpha at the zero angle), nothing along q
    i_alpha = truth[:, f["i_alpha"]]
    assert np.mean(i_alpha[400 + n_level // 2:400 + n_level]) == pytest.approx(2.0 / 1.005, abs=0.02)
    assert np.mean(i_alpha[400 + 3 * n_level // 2:400 + 2 * n_level]) == pytest.approx(4.0 / 1.005, abs=0.02)
    assert np.max(np.abs(truth[400:, f["i_beta"]])) < 0.1
    assert abs(final_rpm - 1500) < 30
