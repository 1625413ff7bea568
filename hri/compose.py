"""docker-compose.yml, written from the stack's declaration (common/stack.py NODES) and the router.

    python -m hri.compose            # print it
    python -m hri.compose --write    # or: make compose — rewrite docker-compose.yml

The file stays committed and meant to be read: the header, the x- anchors and the router are the template
below, then one block per node from its `Container` (flags, note, mounts). tests/test_stack.py fails when the
committed file is not what this writes.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from common import stack
from common.transport import DEFAULT_ENDPOINT

COMPOSE_FILE = Path(__file__).resolve().parent.parent / "docker-compose.yml"
REGENERATE = "python -m hri.compose --write"
ROUTER_PORT = DEFAULT_ENDPOINT.rsplit(":", 1)[1]

HEADER = """\
# The whole hri-fusion stack: a zenoh router and one container per service, all from the one Dockerfile.
# Written by `{regenerate}` from common/stack.py (NODES): edit those, not this file.
#
#   docker compose up --build -d             # build the image and start everything
#   hri echo 'hri/fusion/**'                 # on the host: fused commands and clarifications
#   hri say "pick up the red candy"          # on the host: type instead of speaking
#   docker compose down
#
# Part of the stack on this host, against a router on another (README "Two hosts"):
#   HRI_REMOTE_ROUTER=tcp/10.0.0.2:{port} docker compose up -d --no-deps vision gesture
# (--no-deps: no local router; HRI_REMOTE_ROUTER: where the remote one listens, a name of its own so that an
# HRI_CONNECT meant for the hri command on this host does not leak into the containers).
#
# Settings (environment or a .env file next to this file):
#   HRI_REMOTE_ROUTER the router the services connect to (default tcp/router:{port}, the router service here)
#   HRI_ROUTER_PORT   host port of the router (default {port})
#   HRI_ROUTER_BIND   host address it is published on (default 127.0.0.1; 0.0.0.0 to reach it from the LAN)
#   HRI_DATA          folder mounted read-only at /data (default ./data: the shipped photos)
#   HRI_MODELS        folder mounted read-only at /models in the vision container (default ./data: no model),
#                     e.g. HRI_MODELS=../shared/models HRI_VISION_ARGS="--backend onnx --model /models/yolox_nano.onnx"
#   HRI_CAMERA_SOURCE what the camera shows (default /data/demo/table.png, looped at 5 fps)
#   HRI_IMAGE         image name (default hri-fusion:latest)
#   HRI_LOG_LEVEL     DEBUG, INFO, WARNING … (default INFO)
#   {args_variables}   extra flags of each service
# Where no registry is reachable, docker/ci.sh builds the python:3.11-slim base and the wheels locally first.
name: hri-fusion

x-hri-image: &hri-image
  image: ${{HRI_IMAGE:-hri-fusion:latest}}
  init: true              # a zenoh process as PID 1 would ignore SIGTERM: tini forwards it
  stop_grace_period: 5s   # services exit within 2 s of SIGTERM

x-hri-service: &hri-service
  <<: *hri-image
  environment:
    HRI_CONNECT: ${{HRI_REMOTE_ROUTER:-tcp/router:{port}}}
    HRI_LOG_LEVEL: ${{HRI_LOG_LEVEL:-INFO}}
  volumes:
    - {data_volume}
  depends_on:
    router:
      condition: service_healthy
  restart: unless-stopped
  pull_policy: never      # the router's build makes the image; nothing to pull

# healthy = the container's service holds its liveliness token on the router
x-liveliness-check: &liveliness-check
  interval: 10s
  timeout: 8s
  retries: 3
  start_period: 60s

services:
  router:
    <<: *hri-image
    build:
      context: .   # the one image every service runs; built once, here
    command: ["python", "-m", "hri.cli", "router", "--listen", "tcp/0.0.0.0:{port}"]
    environment:
      HRI_LISTEN: tcp/0.0.0.0:{port}   # the same, for the healthcheck
      HRI_LOG_LEVEL: ${{HRI_LOG_LEVEL:-INFO}}
    ports:
      - "${{HRI_ROUTER_BIND:-127.0.0.1}}:${{HRI_ROUTER_PORT:-{port}}}:{port}"
    healthcheck:
      test: ["CMD", "python", "docker/healthcheck.py", "router"]
      interval: 5s
      timeout: 4s
      retries: 5
      start_period: 20s
    restart: unless-stopped
"""

DATA_VOLUME = "${HRI_DATA:-./data}:/data:ro"  # every service's; a node's own mounts come after it


def node_flags(node: stack.Node) -> str:
    """The flags part of the node's compose command: its default flags, behind HRI_<NAME>_ARGS unless it opts out."""
    if not node.container.flags_env:
        return node.container.flags
    return f"${{{node.args_variable}:-{node.container.flags}}}"


def node_block(node: stack.Node) -> str:
    lines = [f"  {node.name}:", "    <<: *hri-service"]
    lines += [f"    # {line}" for line in node.container.note.splitlines()]
    if node.opt_in:  # started only with `docker compose --profile <name> up`
        lines.append(f'    profiles: ["{node.name}"]')
    lines.append(f"    command: python -m {node.module} {node_flags(node)}")
    if node.container.mounts:  # a list replaces the anchor's, so it repeats the data volume
        lines += ["    volumes:", f"      - {DATA_VOLUME}", *[f"      - {m}" for m in node.container.mounts]]
    lines += [
        "    healthcheck:",
        "      <<: *liveliness-check",
        f'      test: ["CMD", "python", "docker/healthcheck.py", "{node.name}"]',
    ]
    return "\n".join(lines) + "\n"


def compose_text(nodes: tuple[stack.Node, ...] | None = None) -> str:
    """docker-compose.yml for `nodes` (default: the stack's NODES as they are now)."""
    nodes = stack.NODES if nodes is None else nodes
    args_variables = ", ".join(n.args_variable for n in nodes if n.container.flags_env)
    header = HEADER.format(
        regenerate=REGENERATE, port=ROUTER_PORT, args_variables=args_variables, data_volume=DATA_VOLUME
    )
    return "\n".join([header, *(node_block(n) for n in nodes)])


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m hri.compose", description=__doc__.split("\n\n")[0])
    p.add_argument("--write", action="store_true", help=f"rewrite {COMPOSE_FILE.name} instead of printing it")
    args = p.parse_args(argv)
    text = compose_text()
    if args.write:
        COMPOSE_FILE.write_text(text)
        print(f"wrote {COMPOSE_FILE}", file=sys.stderr)
    else:
        sys.stdout.write(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
