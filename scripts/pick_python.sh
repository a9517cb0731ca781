#!/usr/bin/env bash
# Prints the interpreter scripts/bootstrap.sh makes .venv from:
#   1. $PYTHON when set (it must be Python 3.11 or newer);
#   2. else the distribution's own python3 ($SYSTEM_PYTHON, default /usr/bin/python3) when it
#      is 3.11 or newer;
#   3. else the first python3 on PATH when it is 3.11 or newer.
# Otherwise it names what it found and exits 1.
#
# Why the distribution's before PATH's: it is the interpreter the python3-venv and python3-dev
# packages serve (apt cannot add ensurepip or Python.h to a pyenv or conda build), and Debian
# builds it with PGO and LTO and links libpython into the executable. On this project's CI
# machine, where a pyenv 3.11.7 (a shared libpython, neither PGO nor LTO) comes first on PATH,
# `hil run` started 1.25-1.31x as fast on Debian's 3.11 in two `hil bench` runs, while the
# lockstep periods moved less than the VM's drift (logged 1.00-1.08x, plant alone 1.07-1.16x;
# `python -m bench interpreter`; README, "Measured figures").
set -euo pipefail

version_of() { "$1" -c 'import sys; print("%d.%d" % sys.version_info[:2])' 2>/dev/null || echo "not runnable"; }
at_least_311() { "$1" -c 'import sys; sys.exit(sys.version_info < (3, 11))' >/dev/null 2>&1; }

if [ -n "${PYTHON:-}" ]; then
  if ! at_least_311 "$PYTHON"; then
    echo "bootstrap: PYTHON=$PYTHON is $(version_of "$PYTHON"), not a Python 3.11 or newer" >&2
    exit 1
  fi
  echo "$PYTHON"
  exit 0
fi
system=${SYSTEM_PYTHON:-/usr/bin/python3}
if at_least_311 "$system"; then
  echo "$system"
  exit 0
fi
if at_least_311 python3; then
  command -v python3
  exit 0
fi
echo "bootstrap: no Python 3.11 or newer: $system is $(version_of "$system")," \
     "python3 on PATH is $(version_of python3); install one, or set PYTHON=/path/to/python3.11" >&2
exit 1
