#!/usr/bin/env bash
# Writes the lock files from pyproject.toml's ranges (a developer's step, not bootstrap's):
#   requirements.lock          runtime + [test] + [design] + build backend: what `make` installs
#   requirements-runtime.lock  runtime only: what tests/test_import_runtime.py installs
# uv resolves for CPython 3.11 on Linux and writes every wheel's hash (--generate-hashes),
# so pip installs them with --require-hashes. uv is used here only; install it with
# `python3 -m pip install uv`.
set -euo pipefail
cd "$(dirname "$0")/.."
UV=${UV:-uv}
common=(--quiet --generate-hashes --python-version 3.11 --python-platform x86_64-unknown-linux-gnu
        --no-header --emit-index-annotation)
"$UV" pip compile "${common[@]}" pyproject.toml -o requirements-runtime.lock
# setuptools and wheel: `pip install --no-build-isolation -e .` builds with the locked backend
printf 'setuptools>=77\nwheel\n' > /tmp/hil-build-backend.in
"$UV" pip compile "${common[@]}" --extra test --extra design pyproject.toml /tmp/hil-build-backend.in \
  -o requirements.lock
