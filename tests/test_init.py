"""`hil init`: a user's bench project from nameplate values (issue 13)."""
from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import pytest

from hil.cli.init import Nameplate, derive
from hil.cli.main import main as hil_main
from hil.plans.format import load_plan, plan_files

REPO = Path(__file__).resolve().parents[1]


def hil(*args: str, cwd: Path = REPO) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "hil.cli.main", *args], capture_output=True,
                          text=True, timeout=300, cwd=cwd)


def test_default_project_validates_and_passes_on_the_stub(tmp_path):
    """Defaults are the paper's motor: the stub, designed for it, must pass the derived limits."""
    project = tmp_path / "bench"
    assert hil_main(["init", str(project)]) == 0
    for rel in ("profile.yaml", "README.md", ".github/workflows/hil.yml", ".gitlab-ci.yml"):
        assert (project / rel).is_file(), rel
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


def test_the_derived_limits_fail_a_motor_that_is_not_the_nameplate(tmp_path):
    """The speed step's rise-time limit comes from J: a plant with three times the inertia
    (the nameplate is wrong, or the load is coupled) fails it."""
    project = tmp_path / "bench"
    assert hil_main(["init", str(project)]) == 0
    heavy = tmp_path / "heavy.yaml"
    heavy.write_text((project / "profile.yaml").read_text().replace("inertia_kgm2: 0.0008",
                                                                     "inertia_kgm2: 0.0024"))
    assert "0.0024" in heavy.read_text()
    proc = hil("run", str(project / "plans" / "01_speed_step.yaml"), "--link", "stub",
               "--profile", str(heavy), "--out", str(tmp_path / "out"), "--no-progress")
    assert proc.returncode == 1, proc.stdout + proc.stderr
    record = json.loads(next((tmp_path / "out").glob("**/result.json")).read_text())
    failed = [c["name"] for c in record["checks"] if c["outcome"] == "FAIL"]
    assert "rise time 10-90 %" in failed


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
    assert "inductance_q_h: 5e-05" in (tmp_path / "bench" / "profile.yaml").read_text()


def test_bad_nameplate_names_file_line_and_key(tmp_path):
    nameplate = tmp_path / "np.yaml"
    nameplate.write_text("pole_pairs: 4\nresistence_ohm: 0.1\n")
    proc = hil("init", str(tmp_path / "bench"), "--nameplate", str(nameplate))
    assert proc.returncode == 2
    assert f"{nameplate}:2: key 'resistence_ohm'" in proc.stderr
    assert "did you mean 'resistance_ohm'" in proc.stderr


def test_a_folder_that_is_not_empty_is_refused(tmp_path):
    (tmp_path / "bench").mkdir()
    (tmp_path / "bench" / "mine.txt").write_text("keep me")
    proc = hil("init", str(tmp_path / "bench"))
    assert proc.returncode == 2 and "not empty" in proc.stderr
    assert (tmp_path / "bench" / "mine.txt").read_text() == "keep me"
