#!/usr/bin/env bash
# Sets up a fresh machine: build tools (Debian packages, if missing), the
# Python venv at .venv with the pinned PyPI packages and the juno command,
# and the FMU at build/JunoRover.fmu.  Safe to run again: it only does
# what is missing or out of date.
set -euo pipefail
cd "$(dirname "$0")/.."

need_apt=()
command -v cmake >/dev/null || need_apt+=(cmake)
command -v cc >/dev/null || need_apt+=(gcc)
command -v ninja >/dev/null || need_apt+=(ninja-build)
python3 -c 'import venv, ensurepip' 2>/dev/null || need_apt+=(python3-venv)
if [ ${#need_apt[@]} -gt 0 ]; then
  SUDO=""
  if [ "$(id -u)" -ne 0 ]; then
    # Without root, install only through a sudo that needs no password; otherwise say exactly
    # what is missing and stop before anything else is done.
    if command -v sudo >/dev/null && sudo -n true 2>/dev/null; then
      SUDO="sudo"
    else
      echo "setup: these Debian packages are missing: ${need_apt[*]}" >&2
      echo "setup: install them as root, then run this again:" >&2
      echo "  sudo apt-get update && sudo apt-get install -y ${need_apt[*]}" >&2
      exit 1
    fi
  fi
  echo "setup: installing Debian packages: ${need_apt[*]}"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq "${need_apt[@]}"
fi

# The pinned packages (python_harness/requirements.txt) are built for Python 3.11 and newer.
if ! python3 -c 'import sys; sys.exit(sys.version_info < (3, 11))'; then
  echo "setup: Python 3.11 or newer is needed (python3 is $(python3 -V 2>&1)); install it and run again" >&2
  exit 1
fi

stamp=.venv/.juno-requirements
if [ ! -x .venv/bin/python ] || ! cmp -s python_harness/requirements.txt "$stamp" 2>/dev/null; then
  echo "setup: creating .venv with the pinned Python packages"
  python3 -m venv .venv
  .venv/bin/python -m pip install -q --upgrade pip
  .venv/bin/python -m pip install -q -r python_harness/requirements.txt
  cp python_harness/requirements.txt "$stamp"
fi
.venv/bin/python -m pip install -q --no-deps -e python_harness

echo "setup: building the FMU"
cmake -S . -B build -G Ninja -DCMAKE_BUILD_TYPE=Release -DJUNO_WERROR="${JUNO_WERROR:-OFF}" >/dev/null
cmake --build build
test -f build/JunoRover.fmu
test -f build/WheelRig.fmu
# The package carries the FMU too (juno/data, ignored by git), so a wheel built from
# python_harness runs outside this checkout.
mkdir -p python_harness/juno/data
cp build/JunoRover.fmu python_harness/juno/data/JunoRover.fmu
cp build/WheelRig.fmu python_harness/juno/data/WheelRig.fmu
echo "setup: done (build/JunoRover.fmu, build/WheelRig.fmu, .venv/bin/juno)"
