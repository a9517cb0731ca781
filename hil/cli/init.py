"""`hil init DIR`: a bench project for a user's own motor and firmware.

From nameplate values (options or a small YAML file) it writes a bench profile (the motor, and
the control period and sensors scaled to it), a board file for the bench's reference stub on
that motor (its constants and gains derived from the nameplate: hil.design.stub_tuning), a
board file to fill in for the user's own firmware, the plans (hil.cli.init_plans: the standard
plans that run on any motor, copied to name the project's profile and board file, and starter
plans for what no portable standard plan covers; every limit a formula of the profile and the
board file, none a number of the nameplate), CI files for GitHub Actions and GitLab CI, and a
README that says how to put the firmware in the loop through each link. Every derived value is
printed with its formula.

Conventions of the inputs (SI units unless the name says otherwise):
- the back-EMF constant is the line-to-line RMS voltage per 1000 rpm (what most data sheets
  call Ke); the magnet flux linkage is psi_f = Ke sqrt(2/3) / (p w_1000), w_1000 = 2 pi 1000/60;
- inductances are per phase (Ls = L - M for a surface-magnet machine);
- the current limit is the peak phase current the firmware allows (the torque limit follows).
"""
from __future__ import annotations

import argparse
import math
from dataclasses import dataclass, fields
from pathlib import Path

from configfile.schema import POSITIVE, SchemaChecker, obj
from configfile.source import ConfigError, load_yaml

from hil.cli.init_plans import project_plans
from hil.design.stub_tuning import Motor, StubTuning, tune_stub

NAMEPLATE_SCHEMA = obj({
    "pole_pairs": {"type": "integer", "minimum": 1},
    "resistance_ohm": POSITIVE, "inductance_h": POSITIVE, "ld_h": POSITIVE, "lq_h": POSITIVE,
    "flux_linkage_wb": POSITIVE, "back_emf_v_per_krpm": POSITIVE, "inertia_kgm2": POSITIVE,
    "rated_speed_rpm": POSITIVE, "dc_link_v": POSITIVE, "current_limit_a": POSITIVE,
    "control_period_s": {"type": "number", "minimum": 1e-6, "maximum": 1e-2},
    "encoder_lines_per_rev": {"type": "integer", "minimum": 1, "maximum": 16384},
    "name": {"type": "string", "minLength": 1},
})


@dataclass
class Nameplate:
    """The paper's Table 1 motor unless told otherwise."""

    name: str = "my-motor"
    pole_pairs: int = 1
    resistance_ohm: float = 0.466
    inductance_h: float | None = 4.8e-3
    ld_h: float | None = None
    lq_h: float | None = None
    flux_linkage_wb: float | None = 0.0928
    back_emf_v_per_krpm: float | None = None
    inertia_kgm2: float = 8.0e-4
    rated_speed_rpm: float = 3000.0
    dc_link_v: float = 70.0
    current_limit_a: float | None = None
    control_period_s: float | None = None        # None: derived (hil.design.stub_tuning)
    encoder_lines_per_rev: int | None = None     # None: derived


@dataclass
class Derived:
    """The nameplate's derived quantities, printed and in the README (`lines` says how each was
    computed); the plans compute theirs from profile.yaml and the board file."""

    psi_wb: float
    ld_h: float
    lq_h: float
    torque_limit_nm: float
    current_limit_a: float
    tau_e_s: float
    accel_rad_s2: float
    ramp_s: float
    w_rated_rad_s: float
    max_speed_rpm: float
    sag_fraction: float
    lines: list[str]
    tuning: StubTuning      # the stub on this motor: bench period and sensors, board settings


def derive(n: Nameplate) -> Derived:
    lines = []
    if n.back_emf_v_per_krpm is not None:
        w1000 = 2.0 * math.pi * 1000.0 / 60.0
        psi = n.back_emf_v_per_krpm * math.sqrt(2.0 / 3.0) / (n.pole_pairs * w1000)
        lines.append(f"flux linkage psi_f = Ke sqrt(2/3) / (p w_1000) = {n.back_emf_v_per_krpm:g} * "
                     f"{math.sqrt(2 / 3):.4f} / ({n.pole_pairs} * {w1000:.3f}) = {psi:.5g} Wb")
    else:
        psi = float(n.flux_linkage_wb)
        lines.append(f"flux linkage psi_f = {psi:g} Wb (given)")
    ld = n.ld_h if n.ld_h is not None else n.inductance_h
    lq = n.lq_h if n.lq_h is not None else n.inductance_h
    current = n.current_limit_a
    if current is None:
        # the paper's drive: 2 Nm on the Table 1 motor is 14.4 A; elsewhere 3 x the current
        # that holds 1/10 of the torque at the DC-link-limited speed is no physics: ask.
        current = 2.0 / (1.5 * 1 * 0.0928)
        lines.append(f"current limit {current:.4g} A (not given: the paper's 2 Nm on Table 1; "
                     "pass --current-limit-a for your drive)")
    torque = 1.5 * n.pole_pairs * psi * current
    lines.append(f"torque limit T = 3/2 p psi_f I = 1.5 * {n.pole_pairs} * {psi:.5g} * {current:.4g} "
                 f"= {torque:.4g} N m (surface magnets, i_d = 0)")
    tau = min(ld, lq) / n.resistance_ohm
    lines.append(f"electrical time constant L/R = {min(ld, lq):g} / {n.resistance_ohm:g} = "
                 f"{tau * 1e3:.3g} ms")
    accel = torque / n.inertia_kgm2
    lines.append(f"acceleration at the torque limit T/J = {torque:.4g} / {n.inertia_kgm2:g} = "
                 f"{accel:.4g} rad/s^2")
    w_rated = n.rated_speed_rpm * 2.0 * math.pi / 60.0
    ramp = 0.5 * w_rated / accel
    lines.append(f"torque-limited ramp from half to rated speed: (w_r / 2) / (T/J) = "
                 f"{0.5 * w_rated:.4g} / {accel:.4g} = {ramp * 1e3:.4g} ms")
    w_e_max = n.dc_link_v / (math.sqrt(3.0) * psi)
    max_rpm = w_e_max / n.pole_pairs * 60.0 / (2.0 * math.pi)
    lines.append(f"no-load speed the DC link supports (linear modulation): Vdc / (sqrt(3) psi_f p) "
                 f"= {n.dc_link_v:g} / ({math.sqrt(3):.4f} * {psi:.5g} * {n.pole_pairs}) rad/s = "
                 f"{max_rpm:.0f} rpm")
    # The sag plan holds half the rated speed: the back-EMF there needs sqrt(3) psi p w / Vdc of
    # the bus; sag to twice that (a margin for the IR drop and the current loop), at least 60 %.
    need = math.sqrt(3.0) * psi * n.pole_pairs * 0.5 * w_rated / n.dc_link_v
    sag = min(0.9, max(0.6, 2.0 * need))
    lines.append(f"DC-link sag the half-speed plan must ride through: max(0.6, 2 * sqrt(3) psi_f p "
                 f"(w_r/2) / Vdc) = max(0.6, 2 * {need:.3f}) = {sag:.2f} of {n.dc_link_v:g} V")
    if max_rpm < n.rated_speed_rpm:
        lines.append(f"WARNING: rated speed {n.rated_speed_rpm:g} rpm is above what the DC link "
                     f"supports without field weakening ({max_rpm:.0f} rpm)")
    if abs(ld - lq) > 0.1 * lq:
        lines.append(f"WARNING: Ld = {ld:g} H and Lq = {lq:g} H differ: the stub assumes surface "
                     "magnets (i_d = 0, one Ls) and is tuned with Lq")
    motor = Motor(pole_pairs=n.pole_pairs, resistance_ohm=n.resistance_ohm, inductance_h=lq,
                  flux_linkage_wb=psi, inertia_kgm2=n.inertia_kgm2, rated_speed_rad_s=w_rated,
                  dc_link_v=n.dc_link_v, current_limit_a=current)
    tuning = tune_stub(motor, n.control_period_s, n.encoder_lines_per_rev)
    return Derived(psi, ld, lq, torque, current, tau, accel, ramp, w_rated, max_rpm, sag, lines,
                   tuning)


def _num(value: float) -> str:
    """A float as YAML 1.1 reads it as one: 8e-05 is a string to PyYAML, 8.0e-05 a float."""
    text = f"{value:.9g}"
    mantissa, e, exponent = text.partition("e")
    if e and "." not in mantissa:
        text = f"{mantissa}.0e{exponent}"
    return text


def _profile(n: Nameplate, d: Derived) -> str:
    t = d.tuning
    return f"""# Bench profile for {n.name}, written by `hil init` from its nameplate.
# Every key not listed takes the paper's default (plant_rt/profiles/paper.yaml); see
# docs/plant.md for each section. The control period and the sensors are scaled to the motor
# the way the paper's are to Table 1 (the derivation: README.md); set `sensors` to your
# transducers and ADC. What the bench pushes to the board beyond SPEC's required parameters
# is the board file's (boards/).

timing:
  control_period_s: {_num(t.control_period_s)}

motor:
  pole_pairs: {n.pole_pairs}
  resistance_ohm: {_num(n.resistance_ohm)}
  flux_linkage_wb: {_num(d.psi_wb)}
  inductance_d_h: {_num(d.ld_h)}
  inductance_q_h: {_num(d.lq_h)}
  inertia_kgm2: {_num(n.inertia_kgm2)}
  rated_speed_rpm: {_num(n.rated_speed_rpm)}

dc_link:
  source_voltage_v: {_num(n.dc_link_v)}

sensors:
  current:                      # +-{t.current_full_scale_a:.4g} A on 12 bits
    a_per_count: {_num(t.current_full_scale_a / 2048.0)}
  dc_voltage:                   # {t.dc_voltage_full_scale_v:.4g} V on 12 bits
    v_per_count: {_num(t.dc_voltage_full_scale_v / 4096.0)}
  encoder:
    lines_per_rev: {t.encoder_lines_per_rev}
  overcurrent_trip_a: {_num(t.settings["overcurrent_a"])}
  overvoltage_trip_v: {_num(t.overvoltage_trip_v)}
"""


# The stub's parameter declarations, as firmware_stub/board.yaml has them (a board file has no
# include: tests/test_init.py checks that the two declare the same parameters).
_STUB_PARAMETERS = """capabilities: [GATES, DUTY, TELEMETRY]

parameters:
  standard: [stator_resistance_ohm, stator_inductance_h, magnet_flux_wb, flux_ref_wb,
             flux_band_wb, torque_band_nm, torque_limit_nm, speed_kp_nm_per_rad_s,
             speed_ki_nm_per_rad, speed_lpf_cutoff_hz, ekf_k1, ekf_k2, ekf_k3,
             flux_drift_cutoff_hz, overcurrent_a, encoder_loss_timeout_s]
  vendor:                       # ids, units and ranges as firmware_stub/core/control.c takes them
    control_law: {id: 60, unit: "1", min: 0, max: 1, default: 0,
                  description: "0 = DTC (answers GATES), 1 = FOC (answers DUTY while running)"}
    current_bandwidth_hz: {id: 61, unit: Hz, min: 1, max: 1.0e+5, default: 1000,
                           description: "FOC d-q current loop bandwidth; Kp = Ls wc, Ki = Rs wc"}
    foc_angle_source: {id: 62, unit: "1", min: 0, max: 1, default: 0,
                       description: "FOC rotor angle: 0 = encoder, 1 = EKF angle minus the eq. (25) load angle"}
    dead_time_comp_s: {id: 63, unit: s, min: 0, max: 1.0e-5, default: 0,
                       description: "dead-time compensation by current sign, 0 = off"}
    device_drop_comp_v: {id: 64, unit: V, min: 0, max: 10, default: 0,
                         description: "DTC: device drop compensated in the observer voltage, 0 = off"}
    delay_comp_periods: {id: 65, unit: period, min: 0, max: 1, default: 0,
                         description: "DTC: 1 = answers act one period late (shadow register)"}
    current_zero_cal_periods: {id: 66, unit: period, min: 0, max: 65535, default: 0,
                               description: "start-up current-zero calibration with the bridge off, 0 = off"}
    rs_id_periods: {id: 67, unit: period, min: 0, max: 65535, default: 0,
                    description: "start-up stator-resistance identification, periods per level, 0 = off"}
"""


def _stub_board(n: Nameplate, d: Derived) -> str:
    t = d.tuning
    head = "\n".join("#   " + line for line in t.lines[:4])
    settings = []
    for name, value in t.settings.items():
        settings.append(f"  # {t.notes[name]}")
        settings.append(f"  {name}: {_num(value)}")
    settings_text = "\n".join(settings)
    return f"""# The bench's reference stub (firmware_stub/ in hil-bench) on {n.name}, written by `hil init`:
# the stub's parameters (as its own board file, firmware_stub/board.yaml, declares them) and
# settings derived from the nameplate with the formulas that give the stub's defaults on the
# paper's Table 1 motor (docs/stub.md; hil/design/stub_tuning.py). The bench side of the same
# derivation is in profile.yaml:
{head}
# `hil run plans/ --link stub` runs the plans against the stub with these settings (the plans
# name this file); `--board boards/my-firmware.yaml` runs them against your firmware instead.
name: hil-bench reference stub on {n.name}
description: The paper's DTC drive with the simplified EKF, tuned by hil init for {n.name}.
{_STUB_PARAMETERS}
settings:
{settings_text}
"""


def _my_board(n: Nameplate, d: Derived) -> str:
    return f"""# Your firmware's board file (hil-bench docs/boards.md): what your board takes and what the
# bench pushes to it at every session start besides SPEC's required parameters (the control
# period, the sensor scaling and the pole pairs, from profile.yaml). As written it is a board
# built from protocol/SPEC.md alone: nothing more is pushed. Add the standard parameters your
# board takes, its own, and the settings it needs for {n.name} (boards/stub.yaml shows the
# stub's, derived from the nameplate).
name: my firmware
# capabilities: [DUTY, TELEMETRY]
# parameters:
#   standard: [torque_limit_nm, overcurrent_a]
#   vendor:
#     velocity_lpf_hz: {{id: 300, unit: Hz, min: 1, max: 5000, default: 100}}
# settings:
#   torque_limit_nm: {d.torque_limit_nm:.6g}      # 3/2 p psi_f I (README.md)
"""


# Where CI installs hil-bench from: a pip requirement (`hil init --hil-bench SOURCE`). hil-bench
# is not on PyPI: a wheel built by `pip wheel --no-deps .` in a hil-bench checkout (committed to
# the project, or on a server), or `hil-bench @ git+https://HOST/OWNER/hil-bench@TAG`. Without
# one the install step stops with a message that says so.
_NO_SOURCE_MESSAGE = ("HIL_BENCH is not set: set it in this file to where hil-bench installs from "
                      "(a wheel built by pip wheel --no-deps . in a hil-bench checkout, or "
                      "hil-bench @ git+https://HOST/OWNER/hil-bench@TAG); "
                      "hil init --hil-bench SOURCE writes it")
_INSTALL = ('if [ -z "$HIL_BENCH" ]; then\n  echo "' + _NO_SOURCE_MESSAGE + '" >&2\n  exit 1\nfi\n'
            'python -m pip install "$HIL_BENCH"\n')
_RUN = 'hil run plans --link "$HIL_LINK" --board "$HIL_BOARD" --out out --no-progress'


def _yaml_str(text: str) -> str:
    """A YAML double-quoted scalar (JSON's string syntax is YAML's)."""
    import json

    return json.dumps(text)


def _indent(text: str, spaces: int) -> str:
    return "\n".join(" " * spaces + line for line in text.rstrip("\n").split("\n"))


def _github(source: str) -> str:
    return f"""name: hil
on: [push, pull_request]
env:
  HIL_BENCH: {_yaml_str(source)}        # pip requirement hil-bench installs from
  HIL_LINK: "exec:firmware/build/my-firmware"
  HIL_BOARD: boards/my-firmware.yaml
jobs:
  hil:
    runs-on: ubuntu-latest
    steps:
      - uses: actions/checkout@v4
      - uses: actions/setup-python@v5
        with: {{python-version: "3.11"}}
      - name: install hil-bench
        run: |
{_indent(_INSTALL, 10)}
      - run: make -C firmware            # build your firmware (an executable or a .so)
      - run: {_RUN}
      - uses: actions/upload-artifact@v4
        if: always()
        with: {{name: hil-reports, path: out}}
      - uses: mikepenz/action-junit-report@v4
        if: always()
        with: {{report_paths: out/junit.xml}}
"""


def _gitlab(source: str) -> str:
    return f"""hil:
  image: python:3.11
  variables:
    HIL_BENCH: {_yaml_str(source)}      # pip requirement hil-bench installs from
    HIL_LINK: "exec:firmware/build/my-firmware"
    HIL_BOARD: boards/my-firmware.yaml
  script:
    - |
{_indent(_INSTALL, 6)}
    - make -C firmware                 # build your firmware (an executable or a .so)
    - {_RUN}
  artifacts:
    when: always
    paths: [out]
    reports:
      junit: out/junit.xml
"""


def _readme(n: Nameplate, d: Derived, source: str) -> str:
    derivation = "\n".join("- " + line for line in d.lines)
    tuning = "\n".join("- " + line for line in d.tuning.lines)
    install = (f"`{source}`" if source else
               "not set yet: set `HIL_BENCH` in both files (or run `hil init --hil-bench SOURCE` "
               "again), or their install step stops with a message saying so")
    return f"""# Bench project: {n.name}

Written by `hil init`.

| file | what |
|---|---|
| `profile.yaml` | the plant: your motor on the paper's inverter, with the control period and the sensors scaled to it (set `sensors` to your transducers and ADC) |
| `boards/stub.yaml` | the bench's reference stub on this motor: its parameters and settings derived from the nameplate (below) |
| `boards/my-firmware.yaml` | your firmware's board file, to fill in (hil-bench docs/boards.md) |
| `plans/` | hil-bench's standard speed step (`01_speed_step_sensored.yaml`, copied: only its `profile:` and `board:` name this project's files) and three starter plans (steady state, encoder loss, DC-link sag); every limit is a formula of `profile.yaml` and the board file, evaluated before each run, and each plan's description says how |
| `.github/workflows/hil.yml`, `.gitlab-ci.yml` | CI for GitHub Actions and GitLab CI: install hil-bench, build your firmware, run the plans on it, publish the JUnit XML |

```sh
hil plans plans/                                      # validate
hil run plans/ --link stub                            # the bench's stub on this motor (boards/stub.yaml)
hil run plans/ --link exec:path/to/your-firmware --board boards/my-firmware.yaml
```

Each plan names `board: ../boards/stub.yaml`, so on the stub's links it runs the stub with the
settings derived here. `--board FILE` overrides a plan's board: with your firmware give your
board file (as the CI files do); without it, your firmware would be sent the stub's settings.

The plans' limits read the board file's settings (`board.torque_limit_nm`,
`board.speed_kp_nm_per_rad_s`, `board.overcurrent_a`, ...; the report and `result.json` list
every input of every limit). With your board file they are your firmware's settings where it
gives them, else SPEC 8.1's defaults (the paper's drive): give your drive's torque limit,
speed-loop gains and trip level in `boards/my-firmware.yaml`'s settings.

## Derived from the nameplate

{derivation}

## The stub on this motor

The stub's defaults (hil-bench firmware_stub/core/defaults.h, derived in docs/stub.md) are
tuned for the paper's Table 1 motor. The same formulas with this nameplate give the bench's
control period and sensors (`profile.yaml`) and the stub's settings (`boards/stub.yaml`); on the
Table 1 nameplate they give the stub's defaults (in brackets):

{tuning}

The flux-drift corner (10 Hz) and the start-up options stay at the stub's defaults.

## CI

hil-bench is not on PyPI. The CI files install it from `HIL_BENCH`, a pip requirement:
{install}. Either a wheel built in a hil-bench checkout (`pip wheel --no-deps -w dist .`; commit
it to this project or put it on a server) or `hil-bench @ git+https://HOST/OWNER/hil-bench@TAG`.
The wheel is pure Python: it carries neither the plant's nor the codec's C extension (the bench
runs them in Python, slower) nor the stub; your firmware is built by `make -C firmware` and
run through `HIL_LINK` with the board file `HIL_BOARD`.

## Putting your firmware in the loop

Write it from the bench's protocol specification (protocol/SPEC.md in hil-bench: HELLO,
PARAM_SET/GET, COMMAND, SAMPLE -> GATES, DUTY or DUTY_LEGS, TELEMETRY, SHUTDOWN; the machine and sensor
conventions in its section 1.1), then pick a link:

| link | your firmware is |
|---|---|
| `exec:PATH[?args=...&transport=serial\\|slcan]` | an executable speaking the protocol on stdin/stdout (the bench puts it on a pseudo-terminal) |
| `lib:PATH.so` | a shared library exporting the firmware ABI of `protocol/c/hil_fw_abi.h` (fastest, in-process) |
| `qemu:IMAGE.elf[?machine=mps2-an386]` | a Cortex-M image for QEMU (UART, trigger on SAMPLE; hil-bench docs/porting.md) |
| `serial:/dev/ttyUSB0?baud=2000000` | a real board on a serial port |
| `can:socketcan:can0?bitrate=1000000` | a real board on CAN through python-can |

examples/sixstep in hil-bench is a small firmware built all three in-loop ways from one
Makefile: copy it as a template.
"""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("dir", type=Path, help="the project folder to create")
    parser.add_argument("--nameplate", type=Path, help="YAML with the values below (keys as the options, _ for -)")
    parser.add_argument("--force", action="store_true", help="write into a folder that is not empty")
    parser.add_argument("--hil-bench", metavar="SOURCE", default="",
                        help="pip requirement the CI files install hil-bench from (a wheel built by "
                             "`pip wheel --no-deps .` in a hil-bench checkout, or "
                             "'hil-bench @ git+https://HOST/OWNER/hil-bench@TAG'); without it their "
                             "install step stops and says so")
    defaults = Nameplate()
    for f in fields(Nameplate):
        kind = (int if f.name in ("pole_pairs", "encoder_lines_per_rev")
                else (str if f.name == "name" else float))
        parser.add_argument(f"--{f.name.replace('_', '-')}", type=kind, default=None,
                            help=f"default {getattr(defaults, f.name)!r}")


_OPTION_RANGES = {"control_period_s": (1e-6, 1e-2), "encoder_lines_per_rev": (1, 16384)}


def _check_option(name: str, value: float) -> None:
    """A number from the command line: finite, positive, and within the range the nameplate
    file's schema gives (ConfigError naming the option)."""
    low, high = _OPTION_RANGES.get(name, (0.0, math.inf))
    if not math.isfinite(value) or value <= 0.0 or not low <= value <= high:
        bound = f"between {low:g} and {high:g}" if name in _OPTION_RANGES else "positive and finite"
        raise ConfigError(f"--{name.replace('_', '-')} {value!r}: must be {bound}", "options")


def nameplate_from(args) -> Nameplate:
    values: dict = {}
    if args.nameplate is not None:
        doc = load_yaml(args.nameplate)
        data = doc.data or {}
        SchemaChecker(doc).check(NAMEPLATE_SCHEMA, data)
        values.update(data)
    for f in fields(Nameplate):
        given = getattr(args, f.name, None)
        if given is not None:
            values[f.name] = given
    for f in fields(Nameplate):
        given = getattr(args, f.name, None)
        if given is not None and f.name != "name":
            _check_option(f.name, given)
    n = Nameplate(**values)
    if "back_emf_v_per_krpm" in values and "flux_linkage_wb" not in values:
        n.flux_linkage_wb = None
    if ("ld_h" in values or "lq_h" in values) and "inductance_h" not in values:
        if n.ld_h is None or n.lq_h is None:
            raise ConfigError("give both ld_h and lq_h (or inductance_h)", str(args.nameplate or "options"))
    if n.flux_linkage_wb is not None and n.back_emf_v_per_krpm is not None:
        raise ConfigError("give flux_linkage_wb or back_emf_v_per_krpm, not both",
                          str(args.nameplate or "options"))
    return n


def init_command(args) -> int:
    import sys

    n = nameplate_from(args)
    target: Path = args.dir
    if target.exists() and any(target.iterdir()) and not args.force:
        print(f"hil init: {target} is not empty (use --force to write into it)", file=sys.stderr)
        return 2
    d = derive(n)
    source = args.hil_bench or ""
    files = {"profile.yaml": _profile(n, d), "README.md": _readme(n, d, source),
             "boards/stub.yaml": _stub_board(n, d), "boards/my-firmware.yaml": _my_board(n, d),
             ".github/workflows/hil.yml": _github(source), ".gitlab-ci.yml": _gitlab(source)}
    files.update({f"plans/{name}": text for name, text in project_plans().items()})
    for rel, text in files.items():
        path = target / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
    print(f"hil init: {n.name} in {target}")
    for line in d.lines:
        print(f"  {line}")
    print("  the stub on this motor (profile.yaml's period and sensors, boards/stub.yaml):")
    for line in d.tuning.lines:
        print(f"  {line}")
    if not source:
        print("  CI: no --hil-bench SOURCE given: set HIL_BENCH in the CI files (README.md)")
    print(f"  wrote {', '.join(sorted(files))}")
    return 0
