"""scripts/pick_python.sh: the interpreter bootstrap makes .venv from ($PYTHON, else the
distribution's python3, else PATH's; each only when 3.11 or newer), and a named error when
none is."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SCRIPT = ROOT / "scripts" / "pick_python.sh"


def fake_python(path: Path, major: int, minor: int) -> Path:
    """A stand-in answering the two questions pick_python.sh asks an interpreter."""
    path.write_text("#!/bin/sh\n"
                    'case "$2" in\n'
                    f'  *exit*) [ {major * 100 + minor} -ge 311 ] ;;\n'
                    f'  *print*) echo "{major}.{minor}" ;;\n'
                    "  *) exit 2 ;;\n"
                    "esac\n")
    path.chmod(0o755)
    return path


def pick(env_extra: dict, path_dir: Path | None = None) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHON", "SYSTEM_PYTHON")}
    env.update(env_extra)
    if path_dir is not None:
        env["PATH"] = f"{path_dir}:/usr/bin:/bin"
    return subprocess.run(["bash", str(SCRIPT)], capture_output=True, text=True, env=env, timeout=30)


def test_python_variable_wins(tmp_path):
    system = fake_python(tmp_path / "system", 3, 12)
    got = pick({"PYTHON": sys.executable, "SYSTEM_PYTHON": str(system)})
    assert got.returncode == 0, got.stderr
    assert got.stdout.strip() == sys.executable


def test_python_variable_too_old_is_an_error_naming_it(tmp_path):
    old = fake_python(tmp_path / "py310", 3, 10)
    got = pick({"PYTHON": str(old), "SYSTEM_PYTHON": sys.executable})
    assert got.returncode == 1
    assert got.stdout == ""
    assert f"PYTHON={old} is 3.10" in got.stderr


def system_and_path(tmp_path: Path, system: tuple[int, int], on_path: tuple[int, int]) -> tuple[Path, Path, Path]:
    """A distribution python3 of version `system` and a python3 of `on_path` in a PATH directory."""
    bindir = tmp_path / "bin"
    bindir.mkdir()
    return fake_python(tmp_path / "system", *system), fake_python(bindir / "python3", *on_path), bindir


def test_distribution_python_before_path(tmp_path):
    system, _, bindir = system_and_path(tmp_path, (3, 11), (3, 13))
    got = pick({"SYSTEM_PYTHON": str(system)}, path_dir=bindir)
    assert got.returncode == 0, got.stderr
    assert got.stdout.strip() == str(system)


def test_path_python_when_distribution_python_too_old(tmp_path):
    system, on_path, bindir = system_and_path(tmp_path, (3, 9), (3, 12))
    got = pick({"SYSTEM_PYTHON": str(system)}, path_dir=bindir)
    assert got.returncode == 0, got.stderr
    assert got.stdout.strip() == str(on_path)


def test_no_python_new_enough_names_both(tmp_path):
    system, _, bindir = system_and_path(tmp_path, (3, 9), (3, 10))
    got = pick({"SYSTEM_PYTHON": str(system)}, path_dir=bindir)
    assert got.returncode == 1
    assert f"{system} is 3.9" in got.stderr and "python3 on PATH is 3.10" in got.stderr
    assert "PYTHON=" in got.stderr
