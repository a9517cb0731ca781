#!/usr/bin/env bash
# Runs a command as on a machine that has only python3, gcc and make (and the few coreutils
# the scripts use): PATH is a temporary directory of links to those programs, nothing else.
# Shows that `make run` needs nothing of the test toolchain, and that the QEMU plan reports
# SKIPPED, naming what is missing, where qemu-system-arm and arm-none-eabi-gcc are absent:
#
#   scripts/bare_machine.sh make run OUT=/tmp/bare-out     # exits 0; qemu-speed-step SKIPPED
#   scripts/bare_machine.sh bash scripts/bootstrap.sh --test --check   # names the test toolchain
#
# The libraries in /usr/lib stay visible (the simulation hides programs, not files), so the
# run part's own checks (Python.h, ensurepip) are the real ones. tests/test_bootstrap_parts.py
# checks the same in pytest.
set -euo pipefail
cd "$(dirname "$0")/.."
[ $# -gt 0 ] || { echo "usage: scripts/bare_machine.sh COMMAND [ARG...]" >&2; exit 2; }
bin=$(mktemp -d)
trap 'rm -rf "$bin"' EXIT
for tool in python3 gcc cc make ld as ar bash sh env uname dirname id sort tr cat mkdir rm \
            touch cp mv sed grep head ls test; do
  found=$(type -P "$tool") && ln -s "$found" "$bin/$tool"
done
env -i PATH="$bin" HOME="${HOME:-/tmp}" LANG=C.UTF-8 "$@"
