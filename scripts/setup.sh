#!/usr/bin/env bash
# Install what fivebar needs on a Debian machine: the AVR toolchain and simavr, Chromium and its
# WebDriver for the web page's browser tests (apt), then the Python package with its test
# extras (pip, editable). Safe to run again; skips what is there.
set -euo pipefail
cd "$(dirname "$0")/.."

APT_PKGS=(gcc-avr avr-libc binutils-avr simavr libsimavr-dev libelf-dev arduino-core-avr avrdude make gcc pkg-config
          chromium chromium-driver)
missing=()
for p in "${APT_PKGS[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  echo "setup: installing Debian packages: ${missing[*]}"
  SUDO=""
  [ "$(id -u)" -eq 0 ] || SUDO="sudo"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"
fi

PY=${PYTHON:-python3}
# Where the installed package lives, asked from outside the checkout (here the current
# directory would shadow a missing or stale install): it must be this checkout.
here=$(pwd -P)
installed=$(cd / && "$PY" -c 'import os, fivebar_host, kinematics, pytest, hypothesis, scipy, ruff, mypy
print(os.path.dirname(os.path.dirname(os.path.realpath(fivebar_host.__file__))))' 2>/dev/null || true)
if [ "$installed" != "$here" ] || ! command -v fivebar >/dev/null \
   || [ pyproject.toml -nt .setup-stamp ]; then
  echo "setup: installing the fivebar Python package with test extras"
  "$PY" -m pip install --quiet --disable-pip-version-check --root-user-action=ignore -e '.[test]'
  touch .setup-stamp
fi
