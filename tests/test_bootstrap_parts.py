"""`make run` needs only what running plans needs; `make test` the whole test toolchain.

A machine with only python3 (with venv and headers), gcc and make is simulated by a PATH that
is a directory of links to those programs and the few coreutils the scripts use: there,
`scripts/bootstrap.sh --run --check` finds every package it asks for, while `--test --check`
names the test toolchain as missing. Nothing is installed (--check never installs).
"""
from __future__ import annotations

import os
import re
import shutil
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
BOOTSTRAP = REPO / "scripts" / "bootstrap.sh"
# What running plans needs, and what bootstrap and make call on the way.
RUN_TOOLS = ("python3", "gcc", "cc", "make", "ld", "as", "ar")
COREUTILS = ("bash", "sh", "env", "uname", "dirname", "id", "sort", "tr", "cat", "mkdir", "rm",
             "touch", "cp", "mv", "sed", "grep", "head", "ls", "test", "[")
TEST_TOOLCHAIN = ("clang", "valgrind", "cppcheck", "arm-none-eabi-gcc", "qemu-system-arm",
                  "socat", "chromium")


def _minimal_path(tmp_path: Path, without: tuple[str, ...] = ()) -> Path:
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    for name in RUN_TOOLS + COREUTILS:
        found = shutil.which(name)
        if found is not None and name not in without:
            (bin_dir / name).symlink_to(found)
    return bin_dir


def _bootstrap(bin_dir: Path, *options: str) -> subprocess.CompletedProcess:
    env = {"PATH": str(bin_dir), "HOME": os.environ.get("HOME", "/tmp"), "LANG": "C.UTF-8"}
    return subprocess.run([str(bin_dir / "bash"), str(BOOTSTRAP), *options], cwd=REPO, env=env,
                          capture_output=True, text=True, timeout=120)


def test_the_run_part_passes_with_python_gcc_and_make_alone(tmp_path):
    bin_dir = _minimal_path(tmp_path)
    for tool in TEST_TOOLCHAIN:
        assert not (bin_dir / tool).exists()
    got = _bootstrap(bin_dir, "--run", "--check")
    assert got.returncode == 0, got.stderr
    present = set(got.stdout.rsplit(": ", 1)[1].split())
    assert present == {"gcc", "make", "python3-venv", "python3-dev"}


def test_the_test_part_names_the_test_toolchain_on_the_same_machine(tmp_path):
    bin_dir = _minimal_path(tmp_path)
    got = _bootstrap(bin_dir, "--test", "--check")
    assert got.returncode == 1
    missing = set(re.search(r"missing Debian packages: (.*)", got.stderr).group(1).split())
    assert {"clang", "valgrind", "cppcheck", "gcc-arm-none-eabi", "qemu-system-arm", "socat",
            "chromium"} <= missing
    assert not missing & {"gcc", "make", "python3-venv", "python3-dev"}


def test_the_run_part_still_demands_gcc(tmp_path):
    got = _bootstrap(_minimal_path(tmp_path, without=("gcc",)), "--run", "--check")
    assert got.returncode == 1
    assert "missing Debian packages: gcc" in got.stderr


def test_make_targets_take_the_parts():
    """`make run` sets itself up with the run part, `make test` (and CI's bootstrap) with all."""
    plan = subprocess.run(["make", "-n", "run", "test"], cwd=REPO, capture_output=True, text=True,
                          timeout=60).stdout
    assert "bootstrap.sh --run" in plan and "bootstrap.sh --test" in plan
    run_only = subprocess.run(["make", "-n", "run"], cwd=REPO, capture_output=True, text=True,
                              timeout=60).stdout
    assert "bootstrap.sh --test" not in run_only and "--run" in run_only


@pytest.mark.parametrize("directory", ["protocol/c", "plant_rt/c", "firmware_stub"])
def test_what_bootstrap_builds_calls_no_test_tool(directory):
    """The C code bootstrap builds (each directory's default target, as bootstrap runs it)
    calls gcc/cc and python only, never a tool of the test toolchain."""
    commands = subprocess.run(["make", "-n", "-B", "-C", directory], cwd=REPO,
                              capture_output=True, text=True, timeout=60).stdout
    assert commands.strip()
    for tool in TEST_TOOLCHAIN + ("arm-none-eabi-ar",):
        assert not re.search(rf"(^|[\s/]){re.escape(tool)}\s", commands, re.M), (tool, directory)
