"""Fidelity: what each non-ideality of a real drive does to the stub, and what its compensation
gives back (docs/fidelity.md prints this module's table; issue 15).

    python -m bench fidelity [--quick]          # JSON, as every bench module
    python -m bench.fidelity [--quick]          # the markdown table of docs/fidelity.md

One closed-loop run per scenario: the stub (libhilstub.so, in process, every protocol byte
through the C codec) on the plant, encoder speed feedback, in lockstep:

  0      enable, 1500 rpm                          (start-up, not measured)
  0.25 s step to 3000 rpm                          Fig. 4 / 6: overshoot, 2 % settling;
                                                   Fig. 9: speed estimate lag on the ramp
  0.45 s ..0.55 s steady 3000 rpm, no load         Fig. 5 / 7: flux and torque ripple;
                                                   Fig. 9: speed estimate noise
  0.55 s back to 1500 rpm, 1 Nm load ramped in 40 ms
  0.90 s ..1.00 s steady 1500 rpm, 1 Nm            Fig. 10: rotor position errors (plan 05's point)

With the start-up resistance identification on (RS_ID_PERIODS, the hardware profile's default),
its periods run before 0, unmeasured, so the drive starts at the same time into the sequence.

Scenarios: the ideal `paper` profile; each non-ideality of `paper-hardware` alone (its value
taken from that profile), with and without its compensation; all of them together
(`paper-hardware` itself) with no, each and both compensations.
"""
from __future__ import annotations

import math
import sys
import time
from pathlib import Path

PROFILES = Path(__file__).resolve().parent.parent / "plant_rt" / "profiles"
PAPER = PROFILES / "paper.yaml"
HARDWARE = PROFILES / "paper-hardware.yaml"

T = 50e-6
RPM = 2 * math.pi / 60

# Board parameters that switch the compensations off (the hardware profile turns them on).
COMP_OFF = {"dead_time_comp_s": 0.0, "device_drop_comp_v": 0.0, "delay_comp_periods": 0.0,
            "current_zero_cal_periods": 0.0, "rs_id_periods": 0.0}


def _hardware_pieces() -> dict[str, dict]:
    """Each non-ideality of paper-hardware.yaml as a profile override on paper.yaml."""
    from plant_rt import load_profile

    hw = load_profile(HARDWARE)
    cur, vdc = hw.sensors.current, hw.sensors.dc_voltage
    return {
        "delay": {"timing": {"computation_delay_s": hw.timing.computation_delay_s}},
        "dead time": {"inverter": {"dead_time_s": hw.inverter.dead_time_s}},
        "device drop": {"inverter": {"device_drop_v": hw.inverter.device_drop_v}},
        "noise": {"sensors": {"current": {"noise_rms_counts": cur.noise_rms_counts},
                              "dc_voltage": {"noise_rms_counts": vdc.noise_rms_counts}}},
        # offsets and gain errors the board does not know (it keeps the nominal zero)
        "offset + gain": {"sensors": {"current": {"offset_counts": cur.offset_counts, "gain": cur.gain},
                                      "dc_voltage": {"offset_counts": vdc.offset_counts, "gain": vdc.gain}},
                          "board": {"current_offset_counts": 2048.0, "vdc_offset_counts": 0.0}},
        "R +20 %": {"motor": {"resistance_ohm": hw.motor.resistance_ohm}},
    }


def scenarios(quick: bool = False) -> list[tuple[str, Path, dict, dict]]:
    """(name, profile, profile overrides, board parameter overrides)."""
    hw = _hardware_pieces()
    dt_comp = {"dead_time_comp_s": 2.0e-6}
    drop_comp = {"device_drop_comp_v": 1.5}
    delay_comp = {"delay_comp_periods": 1.0}
    zero_cal = {"current_zero_cal_periods": 400.0}
    out = [("ideal (paper)", PAPER, {}, {})]
    for name, comp in (("delay", delay_comp), ("dead time", dt_comp), ("device drop", drop_comp),
                       ("noise", None), ("offset + gain", zero_cal), ("R +20 %", None)):
        over = dict(hw[name])
        told = over.pop("board", {})        # what the board is told (its board file's settings)
        out.append((name, PAPER, over, told))
        if comp is not None:
            out.append((f"{name} + comp", PAPER, over, {**told, **comp}))
    out += [
        ("hardware, no comp", HARDWARE, {}, dict(COMP_OFF)),
        ("hardware, dead time + drop comp", HARDWARE, {}, {**COMP_OFF, **dt_comp, **drop_comp}),
        ("hardware, delay comp", HARDWARE, {}, {**COMP_OFF, **delay_comp}),
        ("hardware, all comp but the zero calibration", HARDWARE, {}, {"current_zero_cal_periods": 0.0}),
        ("hardware, all comp but the R identification", HARDWARE, {}, {"rs_id_periods": 0.0}),
        ("hardware, all comp (profile default)", HARDWARE, {}, {}),
    ]
    if quick:
        keep = {"ideal (paper)", "dead time", "dead time + comp", "hardware, no comp",
                "hardware, all comp (profile default)"}
        out = [s for s in out if s[0] in keep]
    return out


def closed_loop(profile_path: Path, overrides: dict, board: dict, seed: int = 1) -> dict:
    """One run of the sequence in the module docstring; figures against the plant's truth."""
    import numpy as np

    from hil.links.stub_library import StubLibraryLink
    from hil.session.board_params import board_parameters, default_board, load_bench_profile
    from plant_rt import TRUTH_FIELDS, Plant
    from protocol.messages import Command, Duty, Gates, ParamSet, ParamValue, Sample, Telemetry

    profile = load_bench_profile(profile_path, overrides or None)
    plant, link = Plant(profile, seed=seed), StubLibraryLink()
    stub = default_board("stub")
    params = {s.name: s.value for s in board_parameters(profile, stub, profile_path.stem)}
    params.update(board)
    for name, value in params.items():
        link.send(ParamSet(stub.param(name).id, float(value)))
        answer = link.recv()
        while answer is not None and not isinstance(answer, ParamValue):
            answer = link.recv()
        if answer is None or answer.status != 0:
            raise RuntimeError(f"board refused {name} = {value}: {answer}")
    f = {name: i for i, name in enumerate(TRUTH_FIELDS)}
    # The start-up resistance identification (RS_ID_PERIODS, two levels and 1 ms with the
    # bridge open) runs before the sequence, unmeasured, so that the drive starts at the same
    # time into it as without one (after the zero calibration, as before).
    rs_id = int(params.get("rs_id_periods", 0))
    startup = 2 * rs_id + 20 if rs_id else 0
    phases = [(startup * T, 1500.0, None, False), (0.25, 1500.0, None, True), (0.30, 3000.0, None, True),
              (0.45, 1500.0, 1.0, True)]
    rows, tms = [], []
    tripped = None
    for duration, rpm, load, measured in phases:
        link.send(Command(1, 0, rpm * RPM, 0.0, 0.0))
        if load is not None:
            plant.load.set_ramp(load, 0.04)
        for _ in range(int(round(duration / T))):
            s = plant.sample()
            link.send(Sample(s.period, s.adc_i1, s.adc_i2, s.adc_vdc, s.encoder, s.status))
            gates, duty, tm = None, None, None
            msg = link.recv()
            while msg is not None:
                if isinstance(msg, Gates):
                    gates = msg.gates
                elif isinstance(msg, Duty):
                    duty = tuple(d / 65535.0 for d in msg.duty)
                elif isinstance(msg, Telemetry):
                    tm = msg
                msg = link.recv()
            if not measured:
                plant.step(gates, duty)
                continue
            rows.append(plant.truth())
            tms.append((tm.speed_ekf_rad_s, tm.speed_lpf_rad_s, tm.speed_raw_rad_s, tm.rotor_pos_conv_rad,
                        tm.rotor_pos_ekf_rad, tm.flux_mag_wb, tm.flux_angle_rad, tm.state))
            if tm.state == 2 and tripped is None:  # HIL_STATE_FAULT
                tripped = len(rows) * T
            plant.step(gates, duty)
    tr, est = np.array(rows), np.array(tms)
    w = tr[:, f["speed_rad_s"]]
    n = lambda s: int(round(s / T))  # noqa: E731
    out: dict = {"tripped_at_s": tripped}
    # Fig. 4 / 6: the 1500 -> 3000 rpm step
    lo, hi = 1500 * RPM, 3000 * RPM
    seg = w[n(0.25):n(0.55)]
    outside = np.nonzero(np.abs(seg - hi) > 0.02 * (hi - lo))[0]
    out["overshoot_pct"] = 100 * (seg.max() - hi) / (hi - lo)
    out["settling_2pct_ms"] = 1e3 * (outside[-1] + 1) * T if len(outside) else 0.0
    # Fig. 9: lag of the filtered estimates on the ramp (truth between 1700 and 2800 rpm):
    # mean(w - w_est) / mean(dw/dt); noise: rms error in the 3000 rpm steady state
    ramp = np.arange(n(0.25), n(0.55))
    ramp = ramp[(w[ramp] > 1700 * RPM) & (w[ramp] < 2800 * RPM)]
    slope = np.mean(np.gradient(w, T)[ramp]) if len(ramp) > 2 else float("nan")
    steady_hi = slice(n(0.45), n(0.55))
    steady_lo = slice(n(0.90), n(1.00))
    for j, name in ((0, "ekf"), (1, "lpf")):
        out[f"{name}_lag_ms"] = 1e3 * float(np.mean(w[ramp] - est[ramp, j]) / slope) if len(ramp) > 2 else float("nan")
        out[f"{name}_speed_rms_rad_s"] = float(np.sqrt(np.mean((est[steady_hi, j] - w[steady_hi]) ** 2)))
    out["raw_speed_rms_rad_s"] = float(np.sqrt(np.mean((est[steady_hi, 2] - w[steady_hi]) ** 2)))
    # Fig. 5 / 7: true flux magnitude and torque ripple at 3000 rpm (what the motor does)
    flux = tr[steady_hi, f["flux_mag_wb"]]
    torque = tr[steady_hi, f["torque_nm"]]
    out["flux_mean_wb"] = float(np.mean(flux))
    out["flux_ripple_rms_mwb"] = 1e3 * float(np.std(flux))
    out["torque_ripple_rms_nm"] = float(np.std(torque))
    psi_est = est[steady_hi, 5] * np.exp(1j * est[steady_hi, 6])
    psi = tr[steady_hi, f["psi_alpha"]] + 1j * tr[steady_hi, f["psi_beta"]]
    out["flux_estimate_error_rms_mwb"] = 1e3 * float(np.sqrt(np.mean(np.abs(psi_est - psi) ** 2)))
    # Fig. 10: rotor position at 1500 rpm, 1 Nm (plan 05)
    th = tr[steady_lo, f["theta_e_rad"]]
    for j, name in ((3, "arctan"), (4, "ekf")):
        err = (est[steady_lo, j] - th + np.pi) % (2 * np.pi) - np.pi
        out[f"pos_{name}_rms_deg"] = math.degrees(float(np.sqrt(np.mean(err ** 2))))
        out[f"pos_{name}_mean_deg"] = math.degrees(float(np.mean(err)))
    out["speed_error_1500rpm_1nm_rad_s"] = float(np.mean(w[steady_lo]) - 1500 * RPM)
    return {k: (round(v, 4) if isinstance(v, float) else v) for k, v in out.items()}


def run(quick: bool = False) -> dict:
    results = {}
    for name, path, over, board in scenarios(quick):
        t0 = time.perf_counter()
        results[name] = closed_loop(path, over, board)
        results[name]["wall_s"] = round(time.perf_counter() - t0, 1)
        print(f"fidelity {name}: {results[name]['wall_s']} s", file=sys.stderr)
    return {"scenarios": results,
            "sequence": "encoder feedback; 1500 -> 3000 rpm at 0.25 s; 3000 rpm steady 0.45-0.55 s; "
                        "1500 rpm with 1 Nm from 0.55 s, steady 0.90-1.00 s"}


COLUMNS = [
    ("overshoot %", "overshoot_pct", "{:.1f}"),
    ("settling ms", "settling_2pct_ms", "{:.0f}"),
    ("flux ripple rms mWb", "flux_ripple_rms_mwb", "{:.2f}"),
    ("mean flux mWb", "flux_mean_wb", "{:.1f}", 1e3),
    ("flux est. error rms mWb", "flux_estimate_error_rms_mwb", "{:.2f}"),
    ("torque ripple rms Nm", "torque_ripple_rms_nm", "{:.3f}"),
    ("EKF speed rms rad/s", "ekf_speed_rms_rad_s", "{:.2f}"),
    ("LPF speed rms rad/s", "lpf_speed_rms_rad_s", "{:.2f}"),
    ("raw speed rms rad/s", "raw_speed_rms_rad_s", "{:.0f}"),
    ("EKF lag ms", "ekf_lag_ms", "{:.2f}"),
    ("LPF lag ms", "lpf_lag_ms", "{:.2f}"),
    ("arctan pos. rms deg", "pos_arctan_rms_deg", "{:.2f}"),
    ("EKF pos. rms deg", "pos_ekf_rms_deg", "{:.2f}"),
]


def table(results: dict) -> str:
    head = "| scenario | " + " | ".join(c[0] for c in COLUMNS) + " |"
    lines = [head, "|" + "---|" * (len(COLUMNS) + 1)]
    for name, r in results["scenarios"].items():
        cells = []
        tripped = r.get("tripped_at_s")
        for col in COLUMNS:
            if tripped is not None and tripped < 0.90 and col[1].startswith("pos_"):
                cells.append("tripped")  # the 1500 rpm, 1 Nm window comes after the trip
                continue
            v = r[col[1]] * (col[3] if len(col) > 3 else 1.0)
            cells.append(col[2].format(v))
        trip = f" (tripped at {r['tripped_at_s']:.3f} s)" if r.get("tripped_at_s") else ""
        lines.append(f"| {name}{trip} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


PAPER_PLANS = sorted((Path(__file__).resolve().parent.parent / "test_plans").glob("0[1-6]_*.yaml"))


def hardware_plans() -> list[dict]:
    """The paper plans on paper-hardware (whether or not a plan lists that profile): every
    check's measured value against the limits the plan gives that profile."""
    import tempfile

    from hil.plans.format import load_plan
    from hil.run.runner import run_plan
    from hil.session.board_params import default_board

    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for path in PAPER_PLANS:
            plan = load_plan(path)
            listed = "paper-hardware" in [p.label for p in plan.profiles]
            result, _ = run_plan(plan, out_dir=Path(tmp), reports=False, profile="paper-hardware")
            for c in result.checks:
                limits = _limits_text(c.limits) if c.limits is not None else ""
                if not listed and limits:
                    limits += " (the paper profile's: the plan does not run on this one)"
                rows.append({"plan": path.stem[:2], "check": c.name, "outcome": c.outcome.value,
                             "measured": c.measured, "unit": c.unit, "limits": limits,
                             "source": _limits_source(c)})
    return rows


def _limits_text(limits) -> str:
    """Limits.describe() with four significant digits: a formula's value has fifteen."""
    u = "" if limits.unit == "1" else f" {limits.unit}"
    if limits.comparison == "outside":
        text = f"outside {limits.low:.4g} .. {limits.high:.4g}{u}"
    elif limits.low is not None and limits.high is not None:
        text = f"{limits.low:.4g} .. {limits.high:.4g}{u}"
    elif limits.high is not None:
        text = f"<= {limits.high:.4g}{u}"
    else:
        text = f">= {limits.low:.4g}{u}"
    if limits.marginal:
        text += f" (marginal within {limits.marginal:.4g}{u})"
    return text


def _limits_source(check) -> str:
    """Where a check's bounds come from: a formula of the profile and the board (evaluated for
    this run), a regression bound (measured), an identity (a state or code), or a finding."""
    if check.limits is None or check.role == "finding":
        return "finding"
    if check.role == "regression":
        return "regression"
    bounds = [b for b in ("low", "high") if getattr(check.limits, b) is not None]
    if bounds and all(b in check.formulas for b in bounds):
        return "formula"
    if check.limits.low is not None and check.limits.low == check.limits.high:
        return "identity"
    return "literal"


def plan05_one_error_away() -> dict:
    """Plan 05 on paper-hardware with the resistance error, then the DC-link reading error,
    taken away (profile overrides): how much of the rotor-position bias each one is."""
    import tempfile

    from hil.plans.format import load_plan
    import yaml

    from hil.run.runner import run_plan
    from hil.session.board_params import default_board

    plan = load_plan(PAPER_PLANS[4])
    exact = {"R exact (plant 0.466 ohm)": {"motor": {"resistance_ohm": 0.466}},
             "DC-link reading exact": {"sensors": {"dc_voltage": {
                 "offset_counts": 0.0, "gain": 1.0}}},
             "R identification off (the board's cold R)": {"board": {"rs_id_periods": 0}}}
    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        for name, override in exact.items():
            data = yaml.safe_load(HARDWARE.read_text())
            override = dict(override)
            board = default_board("stub").with_settings(override.pop("board", None))
            for section, values in override.items():
                for key, value in values.items():
                    if isinstance(value, dict):
                        data[section][key].update(value)
                    else:
                        data[section][key] = value
            # named as the profile it varies: the board file's paper-hardware settings apply
            path = Path(tmp) / HARDWARE.name
            path.write_text(yaml.safe_dump(data))
            result, _ = run_plan(plan, out_dir=Path(tmp), reports=False, profile=str(path),
                                 board=board)
            out[name] = {c.name: round(c.measured, 2) for c in result.checks
                         if c.measured is not None and "RMS" in c.name}
    return out


def plans_table(rows: list[dict]) -> str:
    lines = ["| plan | check | outcome | measured | limits (paper-hardware) | limit is |",
             "|---|---|---|---|---|---|"]
    for r in rows:
        m = "-" if r["measured"] is None else f"{r['measured']:.4g} {r['unit']}"
        lines.append(f"| {r['plan']} | {r['check']} | {r['outcome']} | {m} | {r['limits']} | "
                     f"{r['source']} |")
    return "\n".join(lines)


if __name__ == "__main__":
    print(table(run(quick="--quick" in sys.argv[1:])))
    print()
    print(plans_table(hardware_plans()))
    print()
    for name, values in plan05_one_error_away().items():
        print(f"plan 05 on paper-hardware, {name}: " + ", ".join(f"{k} {v} deg" for k, v in values.items()))
