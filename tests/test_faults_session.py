"""Faults switched in a running session: from a plan step, from Modbus and from Python; logged
as events, lifted on time, and each visible in the logged truth (the MCAP file)."""
from __future__ import annotations

import math
import socket
from pathlib import Path

import numpy as np
import pytest

from plant_rt import load_profile

from hil.faults.injector import BIT_OF, MODBUS_BIT_MASK, MODBUS_BITS, apply_fault, apply_fault_bits, injector
from hil.logs.reader import read_log
from hil.plans.format import FAULTS, FaultStep
from hil.session.bench_session import BenchSession, SessionConfig

T = 50e-6
LSB_I = 25.0 / 2048
CPR = 4096
WARMUP = 3000            # 0.15 s: the stub has the motor at about 1000 rpm on its way to 1500


def _session(tmp_path: Path | None = None, **config) -> BenchSession:
    log = None
    if tmp_path is not None:
        tmp_path.mkdir(parents=True, exist_ok=True)
        log = tmp_path / "run.mcap"
    return BenchSession(load_profile(), SessionConfig(link="stub", log_path=log, **config))


def _step(name: str, duration_s: float | None = None, clear: bool = False, **args) -> FaultStep:
    return FaultStep(index=0, line=1, name=name, args=args, duration_s=duration_s, clear=clear)


def _fault_events(session) -> list[dict]:
    return [data for _, kind, data in session.events if kind == "fault"]


# --------------------------------------------------------------------------- the catalogue
def test_every_plan_fault_has_one_modbus_bit_and_valid_defaults():
    assert sorted(BIT_OF) == sorted(FAULTS)
    assert len(set(BIT_OF.values())) == len(FAULTS) and MODBUS_BIT_MASK < 1 << 32
    from hil.faults.injector import validate

    for name, args in MODBUS_BITS.values():
        validate(name, args)          # the Modbus defaults obey the plan schema


# --------------------------------------------------------------------------- a plan step
@pytest.mark.parametrize("bit", sorted(MODBUS_BITS))
def test_plan_step_switches_logs_and_lifts_each_fault_on_time(bit):
    """Every fault, from a plan step with duration_s = 0.5 ms (10 periods, shorter than the
    watchdog's 20): an inject and a lift event 10 periods apart, and the fault's bit in the
    recorded fault.active_bits exactly over those periods; the session keeps going."""
    name, args = MODBUS_BITS[bit]
    with _session() as session:
        session.send_command(enable=True, speed_source="encoder", speed_ref_rpm=1500)
        session.run_periods(WARMUP)
        k0 = session.plant.period
        apply_fault(session, _step(name, duration_s=0.0005, **args))
        assert session.fault_bits == 1 << bit
        session.run_periods(40)
        events = _fault_events(session)
        assert [(e["action"], e["name"], e["period"]) for e in events] == \
            [("inject", name, k0), ("lift", name, k0 + 10)]
        assert events[1]["reason"] == "duration" and events[0]["source"] == "plan"
        assert session.fault_bits == 0 and not injector(session).active
        bits = session.recorder.arrays()["fault.active_bits"][1]
        on = np.flatnonzero(bits)
        assert on[0] == k0 and on[-1] == k0 + 9 and np.all(bits[on] == 1 << bit)
        assert "step" not in vars(session.plant)          # nothing left hooked


def test_clear_step_lifts_every_instance_and_a_new_one_replaces_the_old():
    with _session() as session:
        session.run_periods(10)
        apply_fault(session, _step("sensor_offset", sensor="adc_i1", offset_counts=10))
        apply_fault(session, _step("sensor_offset", sensor="adc_vdc", offset_counts=10))
        apply_fault(session, _step("sensor_offset", sensor="adc_i1", offset_counts=20))
        inj = injector(session)
        assert sorted(inj.active) == ["sensor_offset:adc_i1", "sensor_offset:adc_vdc"]
        assert session.plant.sensors.i1.offset_counts == 2048 + 20     # replaced, not added
        apply_fault(session, _step("sensor_offset", clear=True))
        assert not inj.active and session.plant.sensors.i1.offset_counts == 2048
        assert session.plant.sensors.vdc.offset_counts == 0
        assert [e["reason"] for e in _fault_events(session) if e["action"] == "lift"] == \
            ["replaced", "cleared", "cleared"]


def test_python_api_validates_arguments_with_the_plan_schema():
    with _session() as session:
        inj = injector(session)
        with pytest.raises(ValueError, match="unknown fault 'meteor'.*open_phase"):
            inj.inject("meteor")
        with pytest.raises(ValueError, match=r"fault 'open_phase', phase: 'd' is not one of"):
            inj.inject("open_phase", phase="d")
        with pytest.raises(ValueError, match="fault 'link_drop', arguments: 'rate' is a required"):
            inj.inject("link_drop")
        with pytest.raises(ValueError, match="duration_s"):
            inj.inject("encoder_lost", duration_s=-1.0)
        assert not inj.active and session.fault_bits == 0


def test_link_faults_need_a_byte_link():
    with BenchSession(load_profile(), SessionConfig(link="stub-can")) as session:
        with pytest.raises(ValueError, match="needs a link that carries bytes; 'stub-can'"):
            injector(session).inject("link_drop", rate=0.1)


# --------------------------------------------------------------------------- Modbus
def test_modbus_bits_are_level_triggered_with_their_arguments():
    with _session() as session:
        session.run_periods(10)
        apply_fault_bits(session, (1 << BIT_OF["open_phase"]) | (1 << BIT_OF["dc_link_sag"]))
        assert session.plant.open_phase == "a"
        assert session.plant.dc_source_voltage_v == pytest.approx(49.0)
        apply_fault_bits(session, 1 << BIT_OF["dc_link_sag"])
        assert session.plant.open_phase is None
        apply_fault_bits(session, (1 << BIT_OF["dc_link_sag"]) | (1 << 30))  # bit 30: undefined
        assert any(kind == "fault_bits_refused" for _, kind, _ in session.events)
        apply_fault_bits(session, 0)
        assert session.plant.dc_source_voltage_v == 70.0 and session.fault_bits == 0
        assert {e["source"] for e in _fault_events(session)} == {"modbus"}


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_modbus_coil_injects_a_fault_end_to_end():
    """A Modbus client sets coil 2 (encoder_lost) on a running session: the encoder freezes, the
    active-faults input register reads it back, clearing the coil lifts it."""
    from pymodbus.client import ModbusTcpClient

    from hil.ports.modbus import INPUT_REGISTERS, ControlMailbox, ModbusPort

    port = _free_port()
    mailbox = ControlMailbox()
    active = next(f for f in INPUT_REGISTERS if f.name == "fault_bits_active")
    with _session() as session:
        session.attach_mailbox(mailbox, on_fault_bits=lambda bits: apply_fault_bits(session, bits))
        session.send_command(enable=True, speed_source="ekf", speed_ref_rpm=1000)
        with ModbusPort(mailbox, host="127.0.0.1", port=port, fault_bits_mask=MODBUS_BIT_MASK):
            session.run_periods(2000)
            client = ModbusTcpClient("127.0.0.1", port=port)
            assert client.connect()
            try:
                assert not client.write_coil(BIT_OF["encoder_lost"], True).isError()
                assert client.write_coil(25, True).isError()          # undefined bit: refused
                session.run_periods(400)
                reply = client.read_input_registers(active.address, count=2)
                assert active.decode(reply.registers) == 1 << BIT_OF["encoder_lost"]
                assert not client.write_coil(BIT_OF["encoder_lost"], False).isError()
                session.run_periods(400)
            finally:
                client.close()
    enc = session.recorder.arrays()["sensor.encoder"][1]
    events = [e for e in _fault_events(session) if e["name"] == "encoder_lost"]
    assert [e["action"] for e in events] == ["inject", "lift"]
    frozen = enc[events[0]["period"]:events[1]["period"]]
    assert len(frozen) > 10 and np.all(frozen == frozen[0])
    assert len(np.unique(enc[events[1]["period"]:])) > 10          # moving again


# --------------------------------------------------------------------------- logged truth
def _logged(tmp_path: Path, name: str, args: dict, fault_s: float = 0.03, speed_rpm: float = 1500):
    """Runs the stub at speed, injects the fault for fault_s and returns the log's truth and
    sensors (by period) and the fault's period range."""
    with _session(tmp_path) as session:
        session.send_command(enable=True, speed_source="encoder", speed_ref_rpm=speed_rpm)
        session.run_periods(WARMUP)
        k0 = session.plant.period
        injector(session).inject(name, duration_s=fault_s, **args)
        session.run_periods(round(fault_s / T) + 200)
    data = read_log(tmp_path / "run.mcap")
    truth, sensors = data["/plant/truth"], data["/plant/sensors"]
    assert np.array_equal(sensors["period"], np.arange(len(sensors)))
    events = data["/plan/events"]
    kinds = [(k, a) for k, a in zip(events["kind"], events["action"]) if k == "fault"]
    assert kinds == [("fault", "inject"), ("fault", "lift")]
    return truth, sensors, k0, k0 + round(fault_s / T), data


def _window(col, k0, k1):
    return np.asarray(col[k0:k1], dtype=np.float64)


def test_logged_open_phase(tmp_path):
    truth, _, k0, k1, _ = _logged(tmp_path, "open_phase", {"phase": "a"})
    assert np.all(truth["i_a"][k0:k1] == 0.0)
    assert np.all(truth["i_b"][k0:k1] == -truth["i_c"][k0:k1])
    assert np.max(np.abs(truth["i_b"][k0:k1])) > 1.0
    assert np.max(np.abs(truth["i_a"][k1 + 20:])) > 1.0          # reconnected


def test_logged_gate_stuck_off_leaves_the_leg_on_its_diode(tmp_path):
    """Whenever the board commands A high while the current flows into the motor at A, leg A
    cannot reach DC+ (its switch is stuck off): the current takes A's low diode, v_a = 0, and
    the period's u_alpha = (2 v_a - v_b - v_c) / 3 = -(s_b + s_c) Vdc / 3 instead of Table 2's
    (2 - s_b - s_c) Vdc / 3."""
    truth, _, k0, k1, data = _logged(tmp_path, "gate_stuck", {"switch": "a_high", "state": "off"})
    tel = data["/ctrl/telemetry"]
    gates = dict(zip(tel["period"].tolist(), tel["gates"].tolist()))
    i_a = np.asarray(truth["i_a"], dtype=np.float64)
    u_alpha = np.asarray(truth["u_alpha"], dtype=np.float64)

    def a_high_with_current_in(ks):
        return [k for k in ks if gates.get(k, 0) & 0x01 and i_a[k] > 0.05 and i_a[k + 1] > 0.05]

    def others(k):   # s_b + s_c of the commanded word
        return bool(gates[k] & 0x04) + bool(gates[k] & 0x10)

    hits = a_high_with_current_in(range(k0, k1))
    before = a_high_with_current_in(range(k0 - 2000, k0))
    assert len(hits) >= 3 and len(before) >= 3
    for k in hits:
        assert u_alpha[k + 1] == pytest.approx(-others(k) * 70.0 / 3, rel=1e-6)
    for k in before:
        assert u_alpha[k + 1] == pytest.approx((2 - others(k)) * 70.0 / 3, rel=1e-6)


def test_logged_gate_stuck_on_trips_the_board(tmp_path):
    """C's high switch stuck on: the first time the board turns C's low switch on the leg
    shoots through; the plant's GATE_FAULT bit (0x08) reaches the board, which trips."""
    truth, sensors, k0, k1, data = _logged(tmp_path, "gate_stuck", {"switch": "c_high", "state": "on"})
    status = np.asarray(sensors["status"][k0:k1])
    assert np.any(status & 0x08)
    faults = [e for e in zip(data["/plan/events"]["kind"], data["/plan/events"]["code"])
              if e[0] == "board_fault"]
    assert faults and faults[0][1] == 1


def test_logged_encoder_faults(tmp_path):
    truth, sensors, k0, k1, _ = _logged(tmp_path / "lost", "encoder_lost", {})
    enc = np.asarray(sensors["encoder"])
    assert np.all(enc[k0 + 1:k1] == enc[k0]) and enc[k1 + 10] != enc[k0]

    def unwrapped_truth(truth) -> np.ndarray:
        theta = np.unwrap(np.asarray(truth["theta_m_rad"], dtype=np.float64))
        return np.floor(theta * CPR / (2 * math.pi))

    truth, sensors, k0, k1, _ = _logged(tmp_path / "missing", "encoder_missing_counts",
                                        {"fraction": 0.2, "seed": 3})
    edges = unwrapped_truth(truth)
    deficit = (edges - np.asarray(sensors["encoder"])) % 65536
    moved = edges[k1] - edges[k0]
    assert deficit[k0] == 0 and moved > 500
    assert abs(deficit[k1] - 0.2 * moved) < 4 * math.sqrt(moved * 0.2 * 0.8)
    assert deficit[-1] == deficit[k1]                     # lost counts stay lost

    truth, sensors, k0, k1, _ = _logged(tmp_path / "noise", "encoder_noise", {"std_counts": 4.0})
    err = (np.asarray(sensors["encoder"]) - unwrapped_truth(truth) + 32768) % 65536 - 32768
    assert np.all(err[:k0] == 0) and np.all(err[k1 + 1:] == 0)
    assert np.std(err[k0:k1]) == pytest.approx(4.0, rel=0.15)

    truth, sensors, k0, k1, _ = _logged(tmp_path / "index", "encoder_index_missing", {},
                                        fault_s=0.08)
    index = np.asarray(sensors["status"]) & 0x01
    assert np.sum(index[k0 + 1:k1]) == 0 and np.sum(index[:k0]) >= 1
    theta = np.unwrap(np.asarray(truth["theta_m_rad"], dtype=np.float64))
    assert theta[k1] - theta[k0] > 2 * math.pi         # the rotor did pass its index


@pytest.mark.parametrize("name, args", [
    ("sensor_offset", {"sensor": "adc_i1", "offset_counts": 82}),
    ("sensor_gain", {"sensor": "adc_i1", "gain": 1.1}),
    ("sensor_stuck", {"sensor": "adc_i1", "value_counts": 1500}),
    ("sensor_saturation", {"sensor": "adc_i1", "low_counts": 1900, "high_counts": 2200}),
    ("sensor_noise", {"sensor": "adc_i1", "std_counts": 10.0, "seed": 4}),
])
def test_logged_current_sensor_faults(tmp_path, name, args):
    """adc_i1 against the truth's i_a: code = 2048 + gain i_a / LSB + offset (+ 0.5 count rms)."""
    truth, sensors, k0, k1, _ = _logged(tmp_path, name, args)
    ideal = 2048 + np.asarray(truth["i_a"], dtype=np.float64) / LSB_I
    code = np.asarray(sensors["adc_i1"], dtype=np.float64)
    r = slice(k0, k1)
    assert np.std(code[:k0] - ideal[:k0]) < 0.8                 # healthy before
    if name == "sensor_offset":
        assert np.mean(code[r] - ideal[r]) == pytest.approx(82, abs=0.3)
    elif name == "sensor_gain":
        gain = np.polyfit(ideal[r] - 2048, code[r] - 2048, 1)[0]
        assert gain == pytest.approx(1.1, abs=0.005)
    elif name == "sensor_stuck":
        assert np.all(code[r] == 1500)
    elif name == "sensor_saturation":
        assert code[r].min() >= 1900 and code[r].max() <= 2200
        assert np.any(code[r] == 2200) and np.any(code[r] == 1900)     # it did clip both ways
    else:
        assert np.std(code[r] - ideal[r]) == pytest.approx(math.hypot(0.5, 10.0), rel=0.1)
    assert np.std(code[k1 + 1:] - ideal[k1 + 1:]) < 0.8        # and healthy again


@pytest.mark.parametrize("name, args, expect", [
    ("dc_link_sag", {"fraction": 0.7}, lambda k, t: np.full(len(k), 49.0)),
    ("dc_link_surge", {"fraction": 1.2}, lambda k, t: np.full(len(k), 84.0)),
    ("dc_link_ripple", {"amplitude_v": 7.0, "frequency_hz": 300.0},
     lambda k, t: 70.0 + 7.0 * np.sin(2 * np.pi * 300.0 * (k - 0.5) * T)),
])
def test_logged_dc_link(tmp_path, name, args, expect):
    """The bus voltage sampled at t_k: a sag or surge from the fault's period on, a ripple held
    over each period at its midpoint value (the truth at t_k shows period k-1's); 70 V again
    from the period the fault is lifted."""
    truth, sensors, k0, k1, _ = _logged(tmp_path, name, args)
    k = np.arange(k0 + 1, k1)
    np.testing.assert_allclose(np.asarray(truth["v_dc"][k0 + 1:k1], dtype=np.float64),
                               expect(k, k * T), rtol=1e-6)
    assert np.all(np.asarray(truth["v_dc"][k1:]) == 70.0)
    assert np.all(np.asarray(truth["v_dc"][:k0]) == 70.0)


def _resistance_from_truth(truth, k0: int, k1: int) -> float:
    """R from the logged truth alone: per period, psi(k+1) - psi(k) = u T - R int(i dt), with
    u the period's mean voltage and int(i dt) by the trapezoid; least squares over the window."""
    lhs, rhs = [], []
    for a, b in (("u_alpha", ("psi_alpha", "i_alpha")), ("u_beta", ("psi_beta", "i_beta"))):
        u = np.asarray(truth[a], dtype=np.float64)
        psi = np.asarray(truth[b[0]], dtype=np.float64)
        i = np.asarray(truth[b[1]], dtype=np.float64)
        k = np.arange(k0, k1)
        lhs.append(u[k + 1] * T - (psi[k + 1] - psi[k]))
        rhs.append(0.5 * (i[k] + i[k + 1]) * T)
    lhs, rhs = np.concatenate(lhs), np.concatenate(rhs)
    return float(np.dot(lhs, rhs) / np.dot(rhs, rhs))


def test_logged_resistance_drift_changes_the_plant_not_the_board(tmp_path):
    """The logged truth's voltage balance (eq. (1)) gives R = 0.466 ohm before and 0.699 after
    a +50 % drift; the board was never told (its torque estimate now differs from the truth)."""
    with _session(tmp_path) as session:
        session.param_set("stator_resistance_ohm", 0.466)
        session.send_command(enable=True, speed_source="encoder", speed_ref_rpm=1500)
        session.plant.load.set_constant(1.0)
        session.run_periods(8000)
        k0 = session.plant.period
        injector(session).inject("parameter_drift", parameter="resistance_ohm", factor=1.5)
        session.run_periods(4000)
        assert session.board_params["stator_resistance_ohm"] == pytest.approx(0.466)
    truth = read_log(tmp_path / "run.mcap")["/plant/truth"]
    assert _resistance_from_truth(truth, k0 - 2000, k0 - 1) == pytest.approx(0.466, rel=0.02)
    assert _resistance_from_truth(truth, k0 + 1000, k0 + 3999) == pytest.approx(0.699, rel=0.02)
    arrays = session.recorder.arrays()
    err = arrays["ctrl.torque_est_nm"][1] - np.interp(arrays["ctrl.torque_est_nm"][0],
                                                      arrays["plant.torque_nm"][0],
                                                      arrays["plant.torque_nm"][1])
    n = len(err)
    assert abs(np.mean(err[k0 - 2000:k0])) < 0.01 and np.mean(err[n - 1000:]) > 0.1


def test_logged_inertia_and_load_drift(tmp_path):
    """Doubling the inertia halves the acceleration the same torque gives: at the torque limit
    (a step to 3000 rpm) the logged dw/dt = (T - B w - T_L) / J with the drifted J."""
    rates = {}
    for factor in (1.0, 2.0):
        with _session() as session:
            session.send_command(enable=True, speed_source="encoder", speed_ref_rpm=300)
            session.run_periods(4000)
            injector(session).inject("parameter_drift", parameter="inertia_kgm2", factor=factor)
            k0 = session.plant.period
            session.send_command(speed_ref_rpm=3000)
            session.run_periods(400)
            a = session.recorder.arrays()
        w = a["plant.speed_rad_s"][1][k0:]
        te = a["plant.torque_nm"][1][k0:]
        dw = np.diff(w) / T
        drive = 0.5 * (te[:-1] + te[1:]) - 1e-4 * 0.5 * (w[:-1] + w[1:])
        rates[factor] = np.sum(drive) / np.sum(dw)            # least-squares-free J estimate
    assert rates[1.0] == pytest.approx(8.0e-4, rel=0.01)
    assert rates[2.0] == pytest.approx(16.0e-4, rel=0.01)
    with _session() as session:
        session.plant.load.set_constant(0.4)
        session.run_periods(10)
        injector(session).inject("parameter_drift", parameter="load_torque_nm", factor=1.5,
                                 ramp_s=0.01)
        session.run_periods(400)
        load = session.recorder.arrays()["plant.load_torque_nm"][1]
    assert load[5] == pytest.approx(0.4) and load[-1] == pytest.approx(0.6)
    assert 0.4 < load[110] < 0.6                              # on the ramp


# --------------------------------------------------------------------------- real time
def test_realtime_lifts_after_the_same_number_of_periods():
    cfg = dict(mode="realtime", realtime_period_s=1e-3)
    with _session(**cfg) as session:
        session.run_periods(20)
        k0 = session.plant.period
        injector(session).inject("link_delay", periods=2, duration_s=0.0005)   # 10 periods of T
        session.run_periods(40)
        events = _fault_events(session)
        assert [(e["action"], e["period"]) for e in events] == [("inject", k0), ("lift", k0 + 10)]
        assert session.tap.stats["out_delayed"] > 0 and not session.tap.faults


# --------------------------------------------------------------------------- determinism
def test_faulty_runs_are_identical_bit_for_bit():
    def once():
        with _session(seed=3) as session:
            session.send_command(enable=True, speed_source="ekf", speed_ref_rpm=1200)
            session.run_periods(2000)
            inj = injector(session)
            inj.inject("link_drop", rate=0.05, duration_s=0.02)
            inj.inject("sensor_noise", sensor="adc_i2", std_counts=3.0)
            inj.inject("encoder_missing_counts", fraction=0.05)
            inj.inject("dc_link_ripple", amplitude_v=5.0, frequency_hz=120.0, duration_s=0.03)
            session.run_periods(1500)
            return session.recorder.arrays(), session.link_counters()

    (a, ca), (b, cb) = once(), once()
    assert ca == cb and ca["out_dropped"] > 0
    for name in a:
        np.testing.assert_array_equal(a[name][1], b[name][1], err_msg=name)
