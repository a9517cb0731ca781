#!/usr/bin/env bash
# Sets up the bench on a fresh Debian machine that has python3, gcc and make:
# system packages (apt-get, as root), a .venv with the package installed from the lock file,
# the C code built. Idempotent and quick when nothing changed.
#
#   scripts/bootstrap.sh --run    what running plans needs (`make run`): python3 with venv and
#                                 its headers, gcc, make. QEMU and the Arm toolchain are not
#                                 demanded: the QEMU plan reports SKIPPED, naming them, without.
#   scripts/bootstrap.sh --test   (the default) that and every tool the tests use (`make test`):
#                                 clang with libFuzzer, valgrind, cppcheck, cmocka, QEMU, the Arm
#                                 toolchain, socat, chromium.
#   --check                       only check the packages: name the missing ones, install nothing.
#
# A package counts as present only when every FILE the build takes from it is there, not
# just its binary: clang without libclang-rt-14-dev compiles, then fails to link a fuzzer
# (issue 12). After installing, the same files are checked again and a missing one is named.
# A program is looked for on PATH (CMD:name), so a PATH without it counts as without it.
set -euo pipefail
cd "$(dirname "$0")/.."

mode=test
check_only=0
for arg in "$@"; do
  case $arg in
    --run) mode=run ;;
    --test) mode=test ;;
    --check) check_only=1 ;;
    *) echo "bootstrap: unknown option '$arg'; expected --run, --test and/or --check" >&2; exit 2 ;;
  esac
done

arch=$(uname -m)

# The interpreter .venv is made from ($PYTHON, else the distribution's python3, else PATH's:
# scripts/pick_python.sh says why).
py=$(bash scripts/pick_python.sh)
# Debian package -> files (shell globs) or programs (CMD:) a part uses from it, ';'-separated.
# What running plans needs (`make run`):
declare -A RUN_NEEDED=(
  [gcc]="CMD:gcc"
  [make]="CMD:make"
  # python3 -m venv needs ensurepip's wheels
  [python3-venv]="PYTHON:ensurepip,venv"
  # Python.h: the C codec's extension module (protocol/c/python) is compiled against it
  [python3-dev]="PYINCLUDE:Python.h"
)
# What the tests add (`make test`):
declare -A TEST_NEEDED=(
  [libcmocka-dev]="/usr/include/cmocka.h;/usr/lib/*/libcmocka.so"
  [clang]="CMD:clang"
  # libFuzzer and the sanitizer runtimes that `clang -fsanitize=fuzzer,address,undefined` links
  [libclang-rt-14-dev]="/usr/lib/llvm-*/lib/clang/*/lib/linux/libclang_rt.fuzzer-${arch}.a;/usr/lib/llvm-*/lib/clang/*/lib/linux/libclang_rt.asan-${arch}.a;/usr/lib/llvm-*/lib/clang/*/lib/linux/libclang_rt.ubsan_standalone-${arch}.a"
  # gcc's own sanitizer runtimes (tests built with gcc -fsanitize=address,undefined)
  [libasan8]="/usr/lib/gcc/*/*/libasan.so"
  [libubsan1]="/usr/lib/gcc/*/*/libubsan.so"
  [valgrind]="CMD:valgrind"
  [cppcheck]="CMD:cppcheck"
  [gcc-arm-none-eabi]="CMD:arm-none-eabi-gcc;/usr/lib/gcc/arm-none-eabi/*/thumb/v7e-m+fp/hard/libgcc.a"
  # newlib-nano for the hard-float Cortex-M4F (the QEMU image links --specs=nano.specs -lc -lm)
  [libnewlib-arm-none-eabi]="/usr/lib/arm-none-eabi/newlib/nano.specs;/usr/lib/arm-none-eabi/newlib/thumb/v7e-m+fp/hard/libc_nano.a;/usr/lib/arm-none-eabi/newlib/thumb/v7e-m+fp/hard/libm.a"
  [qemu-system-arm]="CMD:qemu-system-arm"
  [socat]="CMD:socat"
  # headless browser for the report rendering test
  [chromium]="CMD:chromium"
)
declare -A NEEDED=()
for pkg in "${!RUN_NEEDED[@]}"; do NEEDED[$pkg]=${RUN_NEEDED[$pkg]}; done
if [ "$mode" = test ]; then
  for pkg in "${!TEST_NEEDED[@]}"; do NEEDED[$pkg]=${TEST_NEEDED[$pkg]}; done
fi

present() {  # present PKG -> 0 when every file of PKG is there
  local spec f
  IFS=';' read -ra specs <<<"${NEEDED[$1]}"
  for spec in "${specs[@]}"; do
    if [[ $spec == PYINCLUDE:* ]]; then
      local inc
      inc=$("$py" -c 'import sysconfig; print(sysconfig.get_paths()["include"])')
      [ -e "$inc/${spec#PYINCLUDE:}" ] || { MISSING_FILE="$inc/${spec#PYINCLUDE:}"; return 1; }
      continue
    fi
    if [[ $spec == CMD:* ]]; then
      command -v "${spec#CMD:}" >/dev/null || { MISSING_FILE="${spec#CMD:} on PATH"; return 1; }
      continue
    fi
    if [[ $spec == PYTHON:* ]]; then
      "$py" -c "import ${spec#PYTHON:}" >/dev/null 2>&1 || { MISSING_FILE="$py modules ${spec#PYTHON:}"; return 1; }
      continue
    fi
    # shellcheck disable=SC2206
    local matches=( $spec )
    [ -e "${matches[0]}" ] || { MISSING_FILE=$spec; return 1; }
  done
}

missing=()
for pkg in "${!NEEDED[@]}"; do
  present "$pkg" || missing+=("$pkg")
done
if [ "$check_only" = 1 ]; then
  if [ ${#missing[@]} -gt 0 ]; then
    echo "bootstrap --$mode: missing Debian packages: ${missing[*]}" >&2
    exit 1
  fi
  echo "bootstrap --$mode: every package is present: $(printf '%s\n' "${!NEEDED[@]}" | sort | tr '\n' ' ')"
  exit 0
fi
if [ ${#missing[@]} -gt 0 ]; then
  if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
    echo "bootstrap: installing ${missing[*]} with apt-get" >&2
    apt-get update -qq
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
    for pkg in "${missing[@]}"; do
      if ! present "$pkg"; then
        echo "bootstrap: $pkg is installed but $MISSING_FILE is still missing" >&2
        exit 1
      fi
    done
  else
    echo "bootstrap: missing Debian packages: ${missing[*]}" >&2
    echo "bootstrap: install them with: sudo apt-get update && sudo apt-get install -y ${missing[*]}" >&2
    exit 1
  fi
fi

# A .venv made from another interpreter (an older bootstrap, another $PYTHON) is made again.
base_of() { "$1" -c 'import os, sys; print(os.path.realpath(getattr(sys, "_base_executable", sys.executable)))' 2>/dev/null; }
if [ -x .venv/bin/python ] && [ "$(base_of .venv/bin/python)" != "$(base_of "$py")" ]; then
  echo "bootstrap: .venv was made from $(base_of .venv/bin/python); making it again from $(base_of "$py")" >&2
  rm -rf .venv
fi
if [ ! -x .venv/bin/python ]; then
  "$py" -m venv .venv
fi
# The environment CI and users run is the lock file's (hashes checked); the package itself
# is installed on top without resolving again. pyproject.toml keeps compatible ranges.
stamp=.venv/.hil-installed
if [ ! -f "$stamp" ] || [ requirements.lock -nt "$stamp" ] || [ pyproject.toml -nt "$stamp" ]; then
  .venv/bin/python -m pip install -q --disable-pip-version-check --require-hashes -r requirements.lock
  .venv/bin/python -m pip install -q --disable-pip-version-check --no-deps --no-build-isolation -e .
  touch "$stamp"
fi

make -s -C protocol/c
make -s -C plant_rt/c
make -s -C firmware_stub
# The example boards' firmware libraries: `make run` runs their plans over lib: (gcc only).
make -s -C examples/hall_sixstep lib
make -s -C examples/bemf_sixstep lib
# Byte-code for the bench's own packages, as a non-editable pip install would write it: a
# shell that sets PYTHONDONTWRITEBYTECODE (this CI machine's does) otherwise compiles every
# module on every `hil run`, 0.08 s of its start-up (python -m bench session: hil_run_startup).
# Python checks each .pyc against its source, so an edited module is never run stale.
.venv/bin/python -m compileall -q -j 0 hil plant_rt protocol configfile >/dev/null
