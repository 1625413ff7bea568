"""Container health check for docker-compose.yml.

  python docker/healthcheck.py router     healthy when the router's port accepts TCP connections
  python docker/healthcheck.py SERVICE    healthy when THIS container's SERVICE holds its liveliness token
                                          on the router (HRI_CONNECT), i.e. it is connected and running

One try, no retry loop (compose retries); exit 0 healthy, 1 not, with a one-line reason on stdout
(`docker inspect` shows it).
"""

from __future__ import annotations

import os
import socket
import sys


def router_port_open(timeout: float) -> tuple[bool, str]:
    endpoints = [e for e in os.environ.get("HRI_LISTEN", "").split(",") if e] or ["tcp/127.0.0.1:7447"]
    port = int(endpoints[0].rsplit(":", 1)[1])
    try:
        socket.create_connection(("127.0.0.1", port), timeout).close()
        return True, f"router accepts connections on port {port}"
    except OSError as exc:
        return False, f"nothing accepts connections on port {port}: {exc}"


def service_alive(service: str, timeout: float) -> tuple[bool, str]:
    import argparse

    import zenoh

    from common.keys import Keys
    from common.transport import live_tokens, resolve, zenoh_config

    args = resolve(argparse.Namespace(connect=None, listen=None, mode=None, zenoh_config=None, prefix=None))
    keys = Keys(args.prefix)
    zenoh.init_log_from_env_or("error")
    try:
        session = zenoh.open(zenoh_config(args))
    except zenoh.ZError as exc:
        return False, f"cannot reach the router at {', '.join(args.connect)}: {str(exc).split(' at ')[0]}"
    # The runner's default instance is <hostname>-<pid>: match this container's own token, not another
    # container's instance of the same service.
    wanted = os.environ.get("HRI_INSTANCE")
    host_prefix = socket.gethostname() + "-"
    try:
        instances = [instance for _, instance in live_tokens(session, keys, service, timeout)]
    finally:
        session.close()
    mine = [i for i in instances if (i == wanted if wanted else i.startswith(host_prefix))]
    if mine:
        return True, f"{service} {mine[0]} is live"
    others = f" (other instances: {', '.join(instances)})" if instances else ""
    return False, f"no liveliness token for {service} in this container yet{others}"


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if len(argv) != 1:
        print(__doc__)
        return 2
    timeout = float(os.environ.get("HRI_HEALTHCHECK_TIMEOUT", "2"))
    ok, reason = router_port_open(timeout) if argv[0] == "router" else service_alive(argv[0], timeout)
    print(reason)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
