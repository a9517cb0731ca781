"""`hil init`: a user's bench project from nameplate values (issue 13), and the stub tuned
for that motor so the project passes on the stub out of the box (issue "Any board, any motor",
items 6 and 7)."""
from __future__ import annotations

import json
import math
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from hil.boards import load_board
from hil.cli.init import Nameplate, derive
from hil.cli.main import main as hil_main
from hil.plans.format import load_plan, plan_files
from hil.session.board_params import STUB_BOARD_FILE

REPO = Path(__file__).resolve().parents[1]


def hil(*args: str, cwd: Path = REPO) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "hil.cli.main", *args], capture_output=True,
                          text=True, timeout=300, cwd=cwd)


def test_default_project_validates_and_passes_on_the_stub(tmp_path):
    """Defaults are the paper's motor: the stub, designed for it, must pass the derived limits."""
    project = tmp_path / "bench"
    assert hil_main(["init", str(project)]) == 0
    for rel in ("profile.yaml", "README.md", ".github/workflows/hil.yml", ".gitlab-ci.yml",
                "boards/stub.yaml", "boards/my-firmware.yaml"):
        assert (project / rel).is_file(), rel
    assert load_board(project / "boards" / "my-firmware.yaml").settings == ()   # a SPEC board
    assert "controller" not in yaml.safe_load((project / "profile.yaml").read_text())
    plans = plan_files([project / "plans"])
    assert len(plans) == 4
    for p in plans:
        text = load_plan(p).description
        assert "Limit" in text or "Requirement" in text, p.name   # each says where its limits come from
    proc = hil("run", str(project / "plans"), "--link", "stub", "--out", str(tmp_path / "out"),
               "--no-progress")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    results = [json.loads(p.read_text()) for p in (tmp_path / "out").glob("**/result.json")]
    assert len(results) == 4 and all(r["outcome"] == "PASS" for r in results)


def test_back_emf_constant_gives_the_flux_linkage():
    """Ke (line-line RMS per 1000 rpm) -> psi_f = Ke sqrt(2/3) / (p w_1000): a motor with
    4 pole pairs and 7.6 V/krpm has psi_f = 7.6 * 0.8165 / (4 * 104.72) = 14.8 mWb."""
    d = derive(Nameplate(pole_pairs=4, flux_linkage_wb=None, back_emf_v_per_krpm=7.6,
                         current_limit_a=20.0))
    assert d.psi_wb == pytest.approx(7.6 * math.sqrt(2 / 3) / (4 * 2 * math.pi * 1000 / 60))
    assert d.torque_limit_nm == pytest.approx(1.5 * 4 * d.psi_wb * 20.0)
    assert any("Ke sqrt(2/3)" in line for line in d.lines)


def test_another_motor_from_a_nameplate_file_validates(tmp_path):
    nameplate = tmp_path / "np.yaml"
    nameplate.write_text("name: drone-motor\npole_pairs: 7\nresistance_ohm: 0.12\n"
                         "ld_h: 4.0e-5\nlq_h: 5.0e-5\nback_emf_v_per_krpm: 3.2\n"
                         "inertia_kgm2: 2.0e-5\nrated_speed_rpm: 8000\ndc_link_v: 24\n"
                         "current_limit_a: 30\n")
    proc = hil("init", str(tmp_path / "bench"), "--nameplate", str(nameplate))
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "psi_f = Ke sqrt(2/3)" in proc.stdout
    assert hil("plans", str(tmp_path / "bench" / "plans")).returncode == 0
    assert "inductance_q_h: 5.0e-05" in (tmp_path / "bench" / "profile.yaml").read_text()


def test_bad_nameplate_names_file_line_and_key(tmp_path):
    nameplate = tmp_path / "np.yaml"
    nameplate.write_text("pole_pairs: 4\nresistence_ohm: 0.1\n")
    proc = hil("init", str(tmp_path / "bench"), "--nameplate", str(nameplate))
    assert proc.returncode == 2
    assert f"{nameplate}:2: key 'resistence_ohm'" in proc.stderr
    assert "did you mean 'resistance_ohm'" in proc.stderr


@pytest.mark.parametrize("option, value, message", [
    ("--inertia-kgm2", "-1", "--inertia-kgm2 -1.0: must be positive and finite"),
    ("--resistance-ohm", "nan", "--resistance-ohm nan: must be positive and finite"),
    ("--control-period-s", "0.5", "--control-period-s 0.5: must be between 1e-06 and 0.01"),
    ("--encoder-lines-per-rev", "20000", "--encoder-lines-per-rev 20000: must be between 1 and 16384"),
])
def test_bad_option_is_named(tmp_path, option, value, message):
    proc = hil("init", str(tmp_path / "bench"), option, value)
    assert proc.returncode == 2 and message in proc.stderr, proc.stderr
    assert not (tmp_path / "bench").exists()


def test_a_folder_that_is_not_empty_is_refused(tmp_path):
    (tmp_path / "bench").mkdir()
    (tmp_path / "bench" / "mine.txt").write_text("keep me")
    proc = hil("init", str(tmp_path / "bench"))
    assert proc.returncode == 2 and "not empty" in proc.stderr
    assert (tmp_path / "bench" / "mine.txt").read_text() == "keep me"


# ------------------------------------------------------------------ the stub on the nameplate

def _stub_default(name: str) -> float:
    """The stub's own default of a parameter, read over the protocol from libhilstub.so (its
    values come from firmware_stub/core/defaults.h and ctl_params_default)."""
    from hil.links.stub_library import StubLibraryLink
    from protocol.messages import ParamGet, ParamId, ParamValue

    link = StubLibraryLink()
    try:
        link.send(ParamGet(int(ParamId[name.upper()])))
        answer = link.recv()
    finally:
        link.close()
    assert isinstance(answer, ParamValue) and answer.status == 0, name
    return answer.value


def test_table1_nameplate_gives_the_stubs_defaults():
    """The formulas hil init applies to a nameplate are the ones that give the stub's defaults
    on the paper's motor: on Table 1 every setting is within 3 % of the stub's default (the
    speed loop's 5.07 Hz against the stub's round 5 Hz gives Kp +1.3 %, Ki +2.6 %; the 0.985 ms
    torque rise time against its 1 ms moves the EKF gains by under 1.6 %)."""
    tuning = derive(Nameplate()).tuning
    assert len(tuning.settings) == 16
    for name, value in tuning.settings.items():
        assert value == pytest.approx(_stub_default(name), rel=0.03), name
    assert tuning.control_period_s == pytest.approx(_stub_default("control_period_s"))
    assert 4 * tuning.encoder_lines_per_rev == _stub_default("encoder_counts_per_rev")
    assert tuning.current_full_scale_a / 2048 == pytest.approx(_stub_default("current_a_per_count"), rel=0.01)
    assert tuning.dc_voltage_full_scale_v / 4096 == pytest.approx(_stub_default("vdc_v_per_count"))
    assert tuning.overvoltage_trip_v == pytest.approx(90.0)       # paper.yaml's comparator


def test_every_setting_is_explained_in_board_file_readme_and_output(tmp_path, capsys):
    project = tmp_path / "bench"
    assert hil_main(["init", str(project)]) == 0
    printed = capsys.readouterr().out
    board_text = (project / "boards" / "stub.yaml").read_text()
    readme = (project / "README.md").read_text()
    board = load_board(project / "boards" / "stub.yaml")
    tuning = derive(Nameplate()).tuning
    assert {s.name for s in board.settings} == set(tuning.settings)
    for name, note in tuning.notes.items():
        line = f"{name} = {note}"
        assert line in printed and line in readme, name
        assert re.search(rf"# {re.escape(note)}\n  {name}: ", board_text), name
    assert "control period T =" in printed and "control period T =" in readme


def test_stub_board_declares_what_the_stubs_own_board_file_declares(tmp_path):
    """A board file has no include: the parameters are written out, and must stay the stub's."""
    assert hil_main(["init", str(tmp_path / "bench")]) == 0
    ours = load_board(tmp_path / "bench" / "boards" / "stub.yaml")
    stubs = load_board(STUB_BOARD_FILE)
    assert ours.parameters == stubs.parameters
    assert ours.capabilities == stubs.capabilities


# Five motors, plausible data-sheet values of their class (typical values, no one vendor's):
# Ke is the line-to-line RMS back-EMF per 1000 rpm, inductance and resistance per phase, the
# current limit the drive's peak phase current. Each motor runs all four generated plans (the
# gimbal and drone motors at 5 us, the others at 10 or 50 us: 1-2 s a motor in lockstep).
ALL_PLANS = ("01_speed_step_sensored", "02_steady_state", "03_encoder_loss", "04_dc_sag")
MOTORS = {
    # the paper's Table 1 motor (the defaults)
    "paper": ([], ALL_PLANS),
    # gimbal motor, 7 pole pairs on 6S (24 V): many turns of thin wire (ohms, millihenries),
    # Kv about 165 rpm/V, a camera payload's inertia, slow
    "gimbal": (["--pole-pairs", "7", "--dc-link-v", "24", "--resistance-ohm", "2.5",
                "--inductance-h", "1.2e-3", "--back-emf-v-per-krpm", "6", "--inertia-kgm2", "1e-4",
                "--rated-speed-rpm", "1000", "--current-limit-a", "2.5"],
               ALL_PLANS),
    # heavy-lift multirotor outrunner, 24N28P (14 pole pairs) on 4S (16 V), Kv 170 rpm/V,
    # 0.1 ohm and 60 uH per phase, 25 A peak, rotor and propeller
    "drone": (["--pole-pairs", "14", "--dc-link-v", "16", "--resistance-ohm", "0.1",
               "--inductance-h", "60e-6", "--back-emf-v-per-krpm", "4.16", "--inertia-kgm2", "4e-4",
               "--rated-speed-rpm", "2000", "--current-limit-a", "25"],
              ALL_PLANS),
    # gearless e-bike hub motor, 23 pole pairs on 48 V, Kv about 9 rpm/V (430 rpm no-load),
    # 30 A peak, the wheel on the bench (no rider)
    "ebike-hub": (["--pole-pairs", "23", "--dc-link-v", "48", "--resistance-ohm", "0.2",
                   "--inductance-h", "0.3e-3", "--back-emf-v-per-krpm", "78.6",
                   "--inertia-kgm2", "0.05", "--rated-speed-rpm", "300", "--current-limit-a", "30"],
                  ALL_PLANS),
    # 0.75 kW AC servo of the 200 V class (300 V DC link), 4 pole pairs, 3000 rpm, 2.4 N m
    # rated (6.8 A peak), 3 x rated current peak, rotor 1.2e-4 kg m^2 with a load of about 2.5x
    "servo": (["--pole-pairs", "4", "--dc-link-v", "300", "--resistance-ohm", "0.9",
               "--inductance-h", "3.5e-3", "--back-emf-v-per-krpm", "30", "--inertia-kgm2", "4e-4",
               "--rated-speed-rpm", "3000", "--current-limit-a", "20"],
              ALL_PLANS),
}


def _run_plans(project: Path, plans, out: Path, *extra: str) -> list[dict]:
    files = [str(project / "plans" / f"{p}.yaml") for p in plans]
    hil_main(["run", *files, "--link", "stub", "--out", str(out), "--no-progress", *extra])
    return [json.loads(p.read_text()) for p in sorted(out.glob("**/result.json"))]


@pytest.mark.parametrize("motor", sorted(MOTORS))
def test_generated_project_passes_on_the_stub_for_any_motor(tmp_path, motor):
    """hil init on the motor's nameplate, then its plans on the in-process stub: the stub,
    tuned by the board file hil init writes, passes every limit hil init derived."""
    options, plans = MOTORS[motor]
    project = tmp_path / motor
    assert hil_main(["init", str(project), "--name", motor, *options]) == 0
    results = _run_plans(project, plans, tmp_path / "out")
    assert len(results) == len(plans)
    outcomes = {r["plan"]: (r["outcome"], r.get("reason")) for r in results}
    assert all(o == "PASS" for o, _ in outcomes.values()), outcomes


def test_board_option_overrides_the_plans_board(tmp_path):
    """--board replaces the board the plans name (how a user runs them on their firmware): with
    boards/my-firmware.yaml, a SPEC board, the stub keeps its Table 1 defaults on the hub
    motor and trips on overcurrent before it reaches the half speed the plan starts from (the
    plan FAILs naming the trip); the same plan passes with the board file the plans name
    (test_generated_project_passes_on_the_stub_for_any_motor)."""
    options, _ = MOTORS["ebike-hub"]
    project = tmp_path / "hub"
    assert hil_main(["init", str(project), *options]) == 0
    [record] = _run_plans(project, ["01_speed_step_sensored"], tmp_path / "out",
                          "--board", str(project / "boards" / "my-firmware.yaml"))
    assert record["extra"]["board_file"]["name"] == "my firmware"
    assert record["outcome"] == "FAIL", record.get("reason")
    assert "board FAULT 1 OVERCURRENT" in record["reason"]


def test_limits_fail_a_plant_that_is_not_the_nameplate(tmp_path):
    """The servo's project, its profile edited after generation to twice the pole pairs (the
    same flux per pole pair: twice the torque per ampere, half the speed the DC link supports;
    the board file unchanged). The speed step's limits are formulas of the profile and the
    board file, evaluated for the edited profile (the one-period torque rise in torque_peak
    doubles with p), but the board's tuning, made for the nameplate, does not follow: the
    rise time FAILs (not ERROR or TIMEOUT)."""
    options, _ = MOTORS["servo"]
    project = tmp_path / "servo"
    assert hil_main(["init", str(project), "--name", "servo", *options]) == 0
    profile = project / "profile.yaml"
    text = profile.read_text()
    edited = text.replace("  pole_pairs: 4\n", "  pole_pairs: 8\n")
    assert edited != text
    profile.write_text(edited)
    [record] = _run_plans(project, ["01_speed_step_sensored"], tmp_path / "out")
    assert record["outcome"] == "FAIL", record.get("reason")
    failed = {c["name"] for c in record["checks"] if c["outcome"] == "FAIL"}
    assert "rise time 10-90 % (torque-limited)" in failed


def test_a_profile_value_moves_the_derived_limits_in_result_json(tmp_path):
    """The speed step's rise-time limits (the standard plan 01's) are 0.8 J dw / torque_peak ..
    0.8 J dw / T_max / 0.72 with J the profile's: ten times the inertia in profile.yaml
    (nothing else edited) gives ten times the limits in result.json, with the formula and the
    profile's inertia among its inputs."""
    options, _ = MOTORS["servo"]
    project = tmp_path / "servo"
    assert hil_main(["init", str(project), "--name", "servo", *options]) == 0
    plan = [str(project / "plans" / "01_speed_step_sensored.yaml")]

    def rise(out: str) -> dict:
        hil_main(["run", *plan, "--link", "stub", "--out", str(tmp_path / out), "--no-progress"])
        [path] = (tmp_path / out).glob("**/result.json")
        record = json.loads(path.read_text())
        return next(c for c in record["checks"] if c["name"] == "rise time 10-90 % (torque-limited)")

    before = rise("before")
    profile = project / "profile.yaml"
    text = profile.read_text()
    edited = text.replace("  inertia_kgm2: 0.0004\n", "  inertia_kgm2: 0.004\n")
    assert edited != text
    profile.write_text(edited)
    after = rise("after")
    for bound in ("low", "high"):
        assert after["limits"][bound] == pytest.approx(10 * before["limits"][bound], rel=1e-9)
        formula = after["limit_formulas"][bound]
        assert formula["value"] == pytest.approx(after["limits"][bound])
    inputs = {i["name"]: i for i in after["limit_formulas"]["high"]["inputs"]}
    assert inputs["ramp_time"]["value"] == pytest.approx(
        10 * {i["name"]: i for i in before["limit_formulas"]["high"]["inputs"]}["ramp_time"]["value"])
    assert after["limit_formulas"]["high"]["formula"] == "0.8 * ramp_time / 0.72"
    # the constants' own inputs are listed too: the profile's inertia, as the edited file has it
    assert inputs["motor.inertia_kgm2"]["value"] == pytest.approx(0.004)
    assert inputs["motor.inertia_kgm2"]["unit"] == "kgm^2"


def test_a_nameplate_value_moves_the_derived_limits_in_result_json(tmp_path):
    """The nameplate reaches the limits through the board file too: the servo's project with
    half the current limit gets half the stub's torque_limit_nm (3/2 p psi_f I, written into
    boards/stub.yaml), so plan 01's torque-limited ramp J dw / T_max, and the rise time's
    upper limit 0.8 ramp / 0.72 in result.json, are twice as long."""
    options, _ = MOTORS["servo"]
    i = options.index("--current-limit-a")

    def rise(name: str, current_a: str) -> dict:
        project = tmp_path / name
        assert hil_main(["init", str(project), "--name", name,
                         *options[:i], "--current-limit-a", current_a, *options[i + 2:]]) == 0
        [record] = _run_plans(project, ["01_speed_step_sensored"], tmp_path / f"out-{name}")
        return next(c for c in record["checks"] if c["name"] == "rise time 10-90 % (torque-limited)")

    full, half = rise("full", "20"), rise("half", "10")
    # (the board file writes 9 significant digits)
    assert half["limits"]["high"] == pytest.approx(2 * full["limits"]["high"], rel=1e-8)
    inputs_full = {i["name"]: i["value"] for i in full["limit_formulas"]["high"]["inputs"]}
    inputs_half = {i["name"]: i["value"] for i in half["limit_formulas"]["high"]["inputs"]}
    assert inputs_half["board.torque_limit_nm"] == pytest.approx(0.5 * inputs_full["board.torque_limit_nm"],
                                                                 rel=1e-8)


# ------------------------------------------------------------------ the plans hil init writes

def test_the_standard_plans_are_copied_unchanged_but_for_profile_and_board(tmp_path):
    """plans/01_speed_step_sensored.yaml is test_plans/'s file: the same data but for
    `profile:` and `board:` (the project's), and a header naming the source."""
    from hil.cli.init_plans import STANDARD_PLANS

    assert hil_main(["init", str(tmp_path / "bench")]) == 0
    assert STANDARD_PLANS
    for rel in STANDARD_PLANS:
        copy_text = (tmp_path / "bench" / "plans" / Path(rel).name).read_text()
        assert f"# hil-bench's standard plan test_plans/{rel} " in copy_text.splitlines()[0]
        copy = yaml.safe_load(copy_text)
        source = yaml.safe_load((REPO / "test_plans" / rel).read_text())
        assert copy.pop("profile") == "../profile.yaml" and copy.pop("board") == "../boards/stub.yaml"
        for key in ("profile", "profiles", "board"):
            source.pop(key, None)
        assert copy == source
        plan = load_plan(tmp_path / "bench" / "plans" / Path(rel).name)
        assert plan.profile_path == (tmp_path / "bench" / "profile.yaml").resolve()
        assert plan.board_path == (tmp_path / "bench" / "boards" / "stub.yaml").resolve()


def literal_limits_in_project(plans: Path) -> set:
    """What test_limit_formulas walks test_plans/ for, in a generated project's plans: every
    acceptance bound that is a number; and every constant written as a number that is not a
    unit (value 1) nor named *_requirement (a requirement stated as such)."""
    from tests.test_limit_formulas import literal_acceptance_limits

    found = literal_acceptance_limits([plans], root=plans)
    for path in plan_files([plans]):
        for name, raw in (yaml.safe_load(path.read_text()).get("constants") or {}).items():
            value = raw["value"]
            if isinstance(value, (int, float)) and value != 1 and not name.endswith("_requirement"):
                found.add((path.name, f"constant {name}", None))
    return found


def test_generated_plans_have_no_literal_acceptance_limit(tmp_path):
    """Every acceptance limit hil init writes is a formula of the profile and the board file
    (or a constant named *_requirement); the walk fails on a limit or a constant written as a
    number."""
    project = tmp_path / "bench"
    assert hil_main(["init", str(project), "--name", "servo", *MOTORS["servo"][0]]) == 0
    assert literal_limits_in_project(project / "plans") == set()
    # the walk can fail: a literal limit, and a tolerance not named a requirement
    plan = project / "plans" / "04_dc_sag.yaml"
    text = plan.read_text()
    plan.write_text(text.replace('high: "(1 + speed_tolerance_requirement) * speed"', "high: 1530"))
    assert literal_limits_in_project(project / "plans") == {
        ("04_dc_sag.yaml", "speed held through the sag", None)}
    plan.write_text(text.replace("speed_tolerance_requirement", "speed_tolerance"))
    assert literal_limits_in_project(project / "plans") == {
        ("04_dc_sag.yaml", "constant speed_tolerance", None)}


# ------------------------------------------------------------------ CI files

def test_ci_files_without_a_source_stop_and_say_so(tmp_path):
    """No --hil-bench: the install step stops with a message naming HIL_BENCH, not a pip error."""
    assert hil_main(["init", str(tmp_path / "bench")]) == 0
    workflow = yaml.safe_load((tmp_path / "bench" / ".github/workflows/hil.yml").read_text())
    install = next(s for s in workflow["jobs"]["hil"]["steps"] if s.get("name") == "install hil-bench")
    proc = subprocess.run(["bash", "-ec", install["run"]], capture_output=True, text=True, timeout=60,
                          env={**os.environ, "HIL_BENCH": workflow["env"]["HIL_BENCH"]})
    assert proc.returncode == 1 and "HIL_BENCH is not set" in proc.stderr
    gitlab = yaml.safe_load((tmp_path / "bench" / ".gitlab-ci.yml").read_text())
    assert gitlab["hil"]["script"][0] == install["run"]


def _deps_from_this_venv(target: Path) -> Path:
    """A folder of links to this venv's installed distributions, without hil-bench itself (its
    editable install points at this checkout): a fresh venv that lists it in a .pth file has
    hil-bench's dependencies installed, so `pip install` of hil-bench needs no network."""
    import sysconfig

    site = Path(sysconfig.get_paths()["purelib"])
    target.mkdir()
    for entry in site.iterdir():
        name = entry.name.lower()
        if name.endswith(".pth") or "hil_bench" in name or "__editable__" in name \
                or name.startswith(("pip", "setuptools", "_distutils_hack")):
            continue
        (target / entry.name).symlink_to(entry)
    return target


def test_ci_install_and_run_steps_work_in_a_clean_venv(tmp_path):
    """The generated GitHub workflow's steps, run as written in a fresh venv: install
    hil-bench from a wheel built from this checkout by `pip wheel` (the source --hil-bench
    names), build the "firmware" (here a script that runs the stub's hil-stub), run the plans
    on it through exec: with the board file HIL_BOARD names. The dependencies come from this
    venv (no network); hil-bench itself only from the wheel."""
    wheels = tmp_path / "wheels"
    subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q",
                    "-w", str(wheels), str(REPO)], check=True, timeout=300, capture_output=True)
    [wheel] = wheels.glob("hil_bench-*.whl")
    project = tmp_path / "bench"
    assert hil_main(["init", str(project), "--hil-bench", str(wheel)]) == 0
    # the user's firmware: the stub on this motor, so its board file is the stub's
    (project / "firmware").mkdir()
    (project / "firmware" / "Makefile").write_text(
        "build/my-firmware:\n\tmkdir -p build\n"
        f"\tprintf '#!/bin/sh\\nexec {REPO}/firmware_stub/build/hil-stub --stdio\\n' > $@\n"
        "\tchmod +x $@\n")
    shutil.copy(project / "boards" / "stub.yaml", project / "boards" / "my-firmware.yaml")
    for plan in ("02_steady_state", "03_encoder_loss", "04_dc_sag"):   # one plan keeps it short
        (project / "plans" / f"{plan}.yaml").unlink()
    venv = tmp_path / "venv"
    # ensurepip installs pip from the wheel bundled with Python: no network
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True, timeout=300)
    vsite = next((venv / "lib").glob("python3*/site-packages"))
    (vsite / "hil_deps.pth").write_text(str(_deps_from_this_venv(tmp_path / "deps")) + "\n")
    workflow = yaml.safe_load((project / ".github/workflows/hil.yml").read_text())
    env = {k: v for k, v in os.environ.items() if not k.startswith(("PYTHON", "VIRTUAL_ENV", "HIL_"))}
    env.update({k: str(v) for k, v in workflow["env"].items()})
    env["PATH"] = f"{venv / 'bin'}{os.pathsep}{env['PATH']}"
    env["PIP_NO_INDEX"] = "1"                     # offline: everything is here already
    for step in workflow["jobs"]["hil"]["steps"]:
        if "run" not in step:
            continue
        proc = subprocess.run(["bash", "-ec", step["run"]], cwd=project, env=env, capture_output=True,
                              text=True, timeout=300)
        assert proc.returncode == 0, (step["run"], proc.stdout[-3000:], proc.stderr[-3000:])
    # hil-bench ran from the venv's copy, not this checkout
    where = subprocess.run([str(venv / "bin" / "python"), "-c", "import hil; print(hil.__file__)"],
                           env=env, capture_output=True, text=True, timeout=60, cwd=tmp_path)
    assert str(venv) in where.stdout, where.stdout + where.stderr
    record = json.loads(next((project / "out").glob("**/result.json")).read_text())
    assert record["outcome"] == "PASS" and record["link"].startswith("exec:")
    assert (project / "out" / "junit.xml").is_file()
    # hil init from the installed wheel finds the standard plans (package data) and writes
    # the same plans as this checkout's
    installed = tmp_path / "installed"
    proc = subprocess.run([str(venv / "bin" / "hil"), "init", str(installed)], env=env, cwd=tmp_path,
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    ours = tmp_path / "ours"
    assert hil_main(["init", str(ours)]) == 0
    written = sorted(p.name for p in (installed / "plans").iterdir())
    assert written == sorted(p.name for p in (ours / "plans").iterdir())
    for name in written:
        assert (installed / "plans" / name).read_text() == (ours / "plans" / name).read_text(), name
