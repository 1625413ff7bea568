#!/usr/bin/env bash
# Build a local stand-in for `python:3.11-slim` when no image registry is reachable:
# debootstrap Debian bookworm (its python3 is 3.11) -> `docker import`, tagged python:3.11-slim, so the
# project's Dockerfile (`FROM python:3.11-slim`) builds unchanged here and where a registry is reachable.
#
# Like the official image it has `python` and `pip` on PATH and pip installs into the system Python
# (Debian's PEP 668 "externally managed" marker is removed: the container is the environment).
#
# Usage: docker/build-base-image.sh [--force]      (needs root, debootstrap and a running Docker engine)
# Env:   HRI_BASE_IMAGE (default python:3.11-slim), HRI_DEBIAN_MIRROR (default: this host's apt mirror)
set -euo pipefail

IMAGE=${HRI_BASE_IMAGE:-python:3.11-slim}
SUITE=bookworm
say() { printf '[base-image] %s\n' "$*" >&2; }

if [ "${1:-}" != "--force" ] && docker image inspect "$IMAGE" >/dev/null 2>&1; then
    say "$IMAGE is already there ($(docker image inspect -f '{{.Created}}' "$IMAGE" | cut -c1-19)); --force rebuilds it"
    exit 0
fi
[ "$(id -u)" = 0 ] || { say "debootstrap needs root; run as root or build $IMAGE some other way"; exit 1; }
command -v debootstrap >/dev/null || { say "debootstrap is missing: apt-get install debootstrap"; exit 1; }

mirror=${HRI_DEBIAN_MIRROR:-}
if [ -z "$mirror" ]; then
    # the same mirror apt uses on this host (deb822 or one-line format), else Debian's CDN
    mirror=$(sed -n 's/^URIs: *\([^ ]*\/debian\)$/\1/p' /etc/apt/sources.list.d/*.sources 2>/dev/null | head -n1)
    [ -n "$mirror" ] || mirror=$(awk '$1=="deb" && $2 ~ /\/debian\/?$/ {print $2; exit}' /etc/apt/sources.list 2>/dev/null || true)
    mirror=${mirror:-http://deb.debian.org/debian}
fi

rootfs=$(mktemp -d /var/tmp/hri-base-rootfs.XXXXXX)
trap 'rm -rf "$rootfs"' EXIT
say "debootstrap $SUITE from $mirror into $rootfs (a few minutes on a cold cache)"
# minbase + python3 and pip: the official slim image's contents, give or take
debootstrap --variant=minbase --include=python3,python3-pip,ca-certificates,netbase \
    "$SUITE" "$rootfs" "$mirror" >"$rootfs.log" 2>&1 || {
    say "debootstrap failed; last lines of $rootfs.log:"; tail -n 20 "$rootfs.log" >&2; exit 1; }
rm -f "$rootfs.log"

say "trimming and finishing the root file system"
rm -f "$rootfs"/usr/lib/python3*/EXTERNALLY-MANAGED
ln -sf /usr/bin/python3 "$rootfs/usr/local/bin/python"
ln -sf /usr/bin/pip3 "$rootfs/usr/local/bin/pip"
rm -rf "$rootfs"/var/cache/apt/archives/*.deb "$rootfs"/var/lib/apt/lists/* \
       "$rootfs"/usr/share/doc/* "$rootfs"/usr/share/man/* "$rootfs"/usr/share/info/* "$rootfs"/tmp/*
# apt inside the image uses the same mirror
echo "deb $mirror $SUITE main" >"$rootfs/etc/apt/sources.list"

say "docker import -> $IMAGE"
tar -C "$rootfs" --numeric-owner -c . | docker import \
    --change 'ENV LANG=C.UTF-8' \
    --change 'ENV PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin' \
    --change 'CMD ["python3"]' \
    --message "local stand-in for python:3.11-slim: debootstrap $SUITE + python3, pip" \
    - "$IMAGE" >/dev/null
say "built $IMAGE: $(docker run --rm "$IMAGE" python --version 2>&1), $(docker image inspect -f '{{.Size}}' "$IMAGE" | awk '{printf "%.0f MB", $1/1e6}')"
