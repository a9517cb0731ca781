"""Every module of the installed package imports in a venv built from the runtime
dependencies alone (requirements-runtime.lock, no test or design extras), so a module that
needs a package only the tests install fails here instead of at a user's desk.

Slow (a venv and a pip install from the lock, ~1 min from pip's cache), so it runs once per
test session; the project is installed as a wheel, not from the source tree, and the imports
run outside the repository so nothing is picked up from the working directory.
"""
from __future__ import annotations

import os
import shutil
import subprocess
import venv
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
PACKAGES = ("configfile", "plant_rt", "protocol", "hil", "bench")

# Modules that only their host program loads, and that host: pytest loads the plugin through
# its entry point, so the plugin may need pytest and nothing else the runtime set lacks.
HOSTED = {"hil.run.pytest_plugin": "pytest"}

# The venv's own interpreter with nothing of the caller's search path: a PYTHONPATH naming the
# working tree (a developer's shell) would make the imports below find the sources, not the
# installed copy.
CLEAN_ENV = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME", "PYTHONSTARTUP")}

IMPORT_ALL = """
import importlib, pkgutil, sys
hosted = dict(arg.split("=") for arg in sys.argv[1:] if "=" in arg)
failed = []
count = 0
for top in [arg for arg in sys.argv[1:] if "=" not in arg]:
    pkg = importlib.import_module(top)
    assert "site-packages" in pkg.__file__, pkg.__file__   # the installed copy
    for info in pkgutil.walk_packages(pkg.__path__, top + "."):
        if info.name.endswith("__main__"):
            continue
        count += 1
        try:
            importlib.import_module(info.name)
        except ModuleNotFoundError as exc:
            if hosted.get(info.name) != exc.name:
                failed.append(f"{info.name}: {type(exc).__name__}: {exc}")
        except Exception as exc:
            failed.append(f"{info.name}: {type(exc).__name__}: {exc}")
print(count, "modules")
if failed:
    print("\\n".join(failed))
    sys.exit(1)
"""


@pytest.fixture(scope="module")
def runtime_venv(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("runtime-venv")
    venv.EnvBuilder(with_pip=True).create(root)
    python = root / "bin" / "python"
    pip = [str(python), "-m", "pip", "install", "-q", "--disable-pip-version-check"]
    subprocess.run(pip + ["--require-hashes", "-r", str(REPO / "requirements-runtime.lock")],
                   check=True, timeout=600, env=CLEAN_ENV)
    # a copy of the sources: a build in the working tree would leave build/ and *.egg-info there
    source = tmp_path_factory.mktemp("source")
    for name in ("pyproject.toml", "README.md"):
        shutil.copy(REPO / name, source / name)
    for pkg in PACKAGES:
        shutil.copytree(REPO / pkg, source / pkg,
                        ignore=shutil.ignore_patterns("__pycache__", "build", "*.so", "*.o"))
    subprocess.run(pip + ["--no-deps", str(source)], check=True, timeout=600, cwd=root, env=CLEAN_ENV)
    return python


def test_every_module_imports_with_the_runtime_dependencies_only(runtime_venv, tmp_path):
    hosted = [f"{module}={host}" for module, host in HOSTED.items()]
    proc = subprocess.run([str(runtime_venv), "-c", IMPORT_ALL, *PACKAGES, *hosted], cwd=tmp_path,
                          capture_output=True, text=True, timeout=300, env=CLEAN_ENV)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert int(proc.stdout.split()[0]) > 50


def test_the_runtime_venv_lacks_the_test_extras(runtime_venv, tmp_path):
    """The check above means something only if the test packages are really absent."""
    for name in ("pytest", "scipy", "hypothesis"):
        proc = subprocess.run([str(runtime_venv), "-c", f"import {name}"], cwd=tmp_path,
                              capture_output=True, text=True, timeout=60, env=CLEAN_ENV)
        assert proc.returncode != 0, f"{name} is installed in the runtime-only venv"
