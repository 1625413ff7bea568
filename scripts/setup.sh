#!/usr/bin/env bash
# Set-up of a fresh machine, run by `make demo` and `make test`: the Debian packages the demo and tests
# need, then .venv with every Python package, pinned by constraints.txt. Re-running is quick: each step
# is skipped when already done.
set -euo pipefail
cd "$(dirname "$0")/.."

APT_PACKAGES=(espeak-ng sox)          # speech audio for the demo and the speech tests
# `setup.sh --test` (make test) adds what only the tests need: a real browser for `hri view`'s page.
if [ "${1:-}" = "--test" ]; then
    APT_PACKAGES+=(chromium libusb-1.0-0)   # libusb: pyrealsense2's wheel links it (the RealSense test)
fi
PYTHON=${PYTHON:-python3}
VENV=.venv

say() { printf '[setup] %s\n' "$*" >&2; }

missing=()
for pkg in "${APT_PACKAGES[@]}"; do
    dpkg -s "$pkg" >/dev/null 2>&1 || missing+=("$pkg")
done
if ((${#missing[@]})); then
    sudo=""
    if [ "$(id -u)" != 0 ]; then
        command -v sudo >/dev/null || { say "need root (or sudo) to apt-get install ${missing[*]}"; exit 1; }
        sudo=sudo
    fi
    say "installing Debian packages: ${missing[*]}"
    $sudo apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi

if ! "$PYTHON" -c 'import sys; sys.exit(sys.version_info[:2] < (3, 11))'; then
    say "Python >= 3.11 is needed; $PYTHON is $("$PYTHON" --version 2>&1). Set PYTHON=/path/to/python3.11"
    exit 1
fi

stamp="$VENV/.setup-$(cat pyproject.toml constraints.txt scripts/setup.sh | sha256sum | cut -c1-16)"
if [ -f "$stamp" ]; then
    exit 0
fi
if [ ! -x "$VENV/bin/python" ]; then
    say "creating $VENV"
    "$PYTHON" -m venv "$VENV"
fi
say "installing Python packages into $VENV (a minute on a fresh machine)"
"$VENV/bin/python" -m pip install -q --upgrade pip
"$VENV/bin/python" -m pip install -q -c constraints.txt -e ".[all,test]"
# mediapipe's own metadata pins numpy<2 and pulls opencv-contrib; its legacy Hands API runs fine with
# numpy 2 and opencv-python-headless, so it goes in without its dependency list.
"$VENV/bin/python" -m pip install -q --no-deps -c constraints.txt mediapipe
rm -f "$VENV"/.setup-*
touch "$stamp"
say "ready: $VENV"
