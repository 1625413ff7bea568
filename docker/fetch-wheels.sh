#!/usr/bin/env bash
# Download, on the host, every wheel the image needs into docker/wheels/, for the IMAGE's Python
# (CPython 3.11, glibc x86_64) whatever the host runs; the Dockerfile then installs with
# `pip install --no-index --find-links`, so the build needs no network.
#
# The extras come from the Dockerfile's `ARG HRI_EXTRAS=...` line and the pins from constraints.txt,
# so this list cannot drift from what the image installs. Skipped when nothing it depends on changed.
#
# Usage: docker/fetch-wheels.sh [--force]        Env: PYTHON (a python with pip; default .venv/bin/python)
set -euo pipefail
cd "$(dirname "$0")/.."

WHEELS=docker/wheels
PYTHON=${PYTHON:-.venv/bin/python}
[ -x "$PYTHON" ] || PYTHON=python3
# The image's interpreter: bookworm's python3 (and python:3.11-slim) is CPython 3.11 on glibc >= 2.36.
# pip does not widen a manylinux_2_X platform to older ones by itself: list them all.
TARGET=(--only-binary=:all: --implementation cp --python-version 3.11 --abi cp311 --abi abi3 --abi none
        --platform any --platform manylinux1_x86_64 --platform manylinux2010_x86_64 --platform manylinux2014_x86_64)
for minor in $(seq 5 36); do TARGET+=(--platform "manylinux_2_${minor}_x86_64"); done
say() { printf '[wheels] %s\n' "$*" >&2; }

extras=$(sed -n 's/^ARG HRI_EXTRAS=//p' Dockerfile)
[ -n "$extras" ] || { say "no 'ARG HRI_EXTRAS=...' line in the Dockerfile"; exit 1; }
stamp="$WHEELS/.fetched-$(cat pyproject.toml constraints.txt docker/fetch-wheels.sh docker/project-requirements.py \
    <(echo "$extras") | sha256sum | cut -c1-16)"
if [ "${1:-}" != "--force" ] && [ -f "$stamp" ]; then
    say "up to date: $(ls "$WHEELS"/*.whl | wc -l) wheels in $WHEELS ($(du -sh "$WHEELS" | cut -f1))"
    exit 0
fi

mkdir -p "$WHEELS"
reqs=$(mktemp)
trap 'rm -f "$reqs"' EXIT
"$PYTHON" docker/project-requirements.py pyproject.toml --extras "$extras" >"$reqs"
# setuptools/wheel: to build the project itself inside the image without an index
echo "setuptools>=68" >>"$reqs"
echo "wheel" >>"$reqs"
say "downloading wheels for extras [$extras] into $WHEELS (about 200 MB; half a minute on a cold cache)"
log=$WHEELS/.download.log
download() {
    "$PYTHON" -m pip download -q --disable-pip-version-check -d "$WHEELS" "${TARGET[@]}" -c constraints.txt "$@" \
        >>"$log" 2>&1 || { grep -v "is ignored: it is neither" "$log" | tail -n 20 >&2
                          say "pip download failed (full log: $log)"; exit 1; }
}
: >"$log"
download -r "$reqs"
# mediapipe's metadata pins numpy<2 and pulls opencv-contrib: the image installs it with --no-deps, like setup.sh
download --no-deps mediapipe

rm -f "$WHEELS"/.fetched-*
touch "$stamp"
say "ready: $(ls "$WHEELS"/*.whl | wc -l) wheels in $WHEELS ($(du -sh "$WHEELS" | cut -f1))"
