"""Opening a Zenoh session from command-line flags and environment, with retry."""

from __future__ import annotations

import argparse
import json
import logging
import os
import threading
import time
from collections.abc import MutableMapping

import zenoh

from common.keys import DEFAULT_PREFIX, Keys

DEFAULT_ENDPOINT = "tcp/127.0.0.1:7447"

# Links that drop (docs/foundation.md, "Across machines"). A session whose peer is silent for LEASE_MS is closed:
# the router then drops its liveliness tokens (fusion sees the modality gone) and the client reconnects by itself,
# retrying every RETRY_* ms. Zenoh's default lease is 10 s: a 5 s Wi-Fi drop would go unnoticed and every
# sample of it would arrive late in one burst. Keep-alives go out every LEASE_MS / KEEP_ALIVE.
LEASE_MS = 3000
KEEP_ALIVE = 4
RETRY = {"period_init_ms": 250, "period_max_ms": 1000, "period_increase_factor": 2}
# The router's receive pool (docs/foundation.md, "Across machines"). Zenoh reads every link and routes on a pool of
# 2 threads, and closing a session whose host dropped off the network holds one of them for ~10 s (the TCP
# close of a link with unsent data). Two hosts' sessions expiring at once stalled all routing for ~9 s; a third
# longer, past the other clients' 3 s lease, and a command typed meanwhile was lost. Each dropped session holds
# one thread: ROUTER_RX_THREADS leaves room for every service of a few hosts dropping together.
ROUTER_RX_THREADS = 16


def size_router_pools(environ: MutableMapping[str, str] = os.environ) -> str:
    """Give the router's receive pool ROUTER_RX_THREADS workers unless the user sized Zenoh's pools
    (ZENOH_RUNTIME); returns the setting in force. Call before the session opens: Zenoh reads it once."""
    return environ.setdefault("ZENOH_RUNTIME", f"(rx: (worker_threads: {ROUTER_RX_THREADS}))")


# Commands and clarifications published while a link is down: the AdvancedPublisher keeps the last
# RECOVERY_CACHE of them, and announces its last sequence number every HEARTBEAT_S so a subscriber that was cut
# off notices what it missed and fetches it (declare_recovering_subscriber).
RECOVERY_CACHE = 64
HEARTBEAT_S = 0.5

_zenoh_log_started = False


def add_zenoh_arguments(parser: argparse.ArgumentParser) -> None:
    """The flags every process shares. Each also reads an HRI_* environment variable (for compose)."""
    g = parser.add_argument_group("zenoh")
    g.add_argument(
        "--connect",
        action="append",
        default=None,
        metavar="ENDPOINT",
        help=f"router endpoint to connect to, repeatable (env HRI_CONNECT, comma-separated; "
        f"default {DEFAULT_ENDPOINT})",
    )
    g.add_argument(
        "--listen",
        action="append",
        default=None,
        metavar="ENDPOINT",
        help="endpoint to listen on, repeatable (env HRI_LISTEN)",
    )
    g.add_argument(
        "--mode", choices=("client", "peer", "router"), default=None, help="zenoh mode (env HRI_MODE; default client)"
    )
    g.add_argument(
        "--config",
        dest="zenoh_config",
        default=None,
        metavar="FILE",
        help="a zenoh json5 config file; the flags above override it (env HRI_ZENOH_CONFIG)",
    )
    g.add_argument("--prefix", default=None, help=f"key expression prefix (env HRI_PREFIX; default {DEFAULT_PREFIX})")
    g.add_argument(
        "--secure",
        default=None,
        metavar="DIR",
        help="secrets folder of a secured robot (`hri secure init DIR`): log in with --user and its "
        "password from DIR/passwords; a router enforces DIR's access rules (env HRI_SECURE)",
    )
    g.add_argument(
        "--user",
        default=None,
        help="user to log in as with --secure (env HRI_USER; default: the service's name, cli for hri)",
    )


def _env_list(name: str) -> list[str] | None:
    raw = os.environ.get(name, "").strip()
    return [e.strip() for e in raw.split(",") if e.strip()] or None


def resolve(args: argparse.Namespace) -> argparse.Namespace:
    """Fill unset zenoh flags from the environment and defaults, in place."""
    args.connect = args.connect or _env_list("HRI_CONNECT")
    args.listen = args.listen or _env_list("HRI_LISTEN")
    args.mode = args.mode or os.environ.get("HRI_MODE") or "client"
    args.zenoh_config = args.zenoh_config or os.environ.get("HRI_ZENOH_CONFIG") or None
    args.prefix = args.prefix or os.environ.get("HRI_PREFIX") or DEFAULT_PREFIX
    args.secure = getattr(args, "secure", None) or os.environ.get("HRI_SECURE") or None
    args.user = getattr(args, "user", None) or os.environ.get("HRI_USER") or None
    if args.mode == "client" and not args.connect:
        args.connect = [DEFAULT_ENDPOINT]
    return args


def zenoh_config(args: argparse.Namespace) -> zenoh.Config:
    resolve(args)
    if args.zenoh_config:
        try:
            conf = zenoh.Config.from_file(args.zenoh_config)
        except Exception as exc:
            raise SystemExit(f"cannot read zenoh config {args.zenoh_config!r}: {exc}") from None
    else:
        conf = zenoh.Config()
        # Scouting by multicast finds strangers' routers on a shared LAN; we connect where we are told.
        conf.insert_json5("scouting/multicast/enabled", "false")
        link_defaults(conf)
    conf.insert_json5("mode", json.dumps(args.mode))
    if args.connect:
        conf.insert_json5("connect/endpoints", json.dumps(args.connect))
    if args.listen:
        conf.insert_json5("listen/endpoints", json.dumps(args.listen))
    if args.secure:
        add_security(conf, args)
    return conf


def link_defaults(conf: zenoh.Config) -> None:
    """Lease, keep-alive and reconnection of every session we configure (a --config file brings its own)."""
    conf.insert_json5("transport/link/tx/lease", str(LEASE_MS))
    conf.insert_json5("transport/link/tx/keep_alive", str(KEEP_ALIVE))
    conf.insert_json5("connect/retry", json.dumps(RETRY))


def add_security(conf: zenoh.Config, args: argparse.Namespace) -> None:
    """A router: users/passwords and the access rules of the secrets folder. Anything else: log in as --user."""
    from common.security import SecurityError, access_control, login_user, password_for, read_secrets, tls_files

    tls = tls_files(args.secure)  # used on tls/ endpoints only
    if "ca" in tls:
        conf.insert_json5("transport/link/tls/root_ca_certificate", json.dumps(str(tls["ca"])))
    if args.mode == "router" and "cert" in tls and "key" in tls:
        conf.insert_json5("transport/link/tls/listen_certificate", json.dumps(str(tls["cert"])))
        conf.insert_json5("transport/link/tls/listen_private_key", json.dumps(str(tls["key"])))
    try:
        if args.mode == "router":
            sec = read_secrets(args.secure)
            conf.insert_json5("transport/auth/usrpwd/dictionary_file", json.dumps(str(sec.passwords_file)))
            conf.insert_json5("access_control", json.dumps(access_control(sec, args.prefix)))
        else:
            user = login_user(args.secure, args.user or "cli", args.prefix)
            conf.insert_json5("transport/auth/usrpwd/user", json.dumps(user))
            conf.insert_json5("transport/auth/usrpwd/password", json.dumps(password_for(args.secure, user)))
    except SecurityError as exc:
        raise SystemExit(f"hri: {exc}") from None


def init_zenoh_logging() -> None:
    global _zenoh_log_started
    if not _zenoh_log_started:
        zenoh.init_log_from_env_or("error")
        _zenoh_log_started = True


def open_session(
    args: argparse.Namespace,
    log: logging.Logger,
    stop: threading.Event | None = None,
    max_delay: float = 2.0,
    timestamping: bool = False,
) -> zenoh.Session | None:
    """Open a session, retrying with back-off while the router is not up yet.

    `timestamping`: stamp our own samples with this session's HLC (needed by recovering publishers). Off by
    default, so the router stamps what it receives from us with its clock (fusion's clock-offset estimate).
    Returns None if `stop` is set while waiting (the process was asked to quit).
    """
    init_zenoh_logging()
    conf = zenoh_config(args)
    if timestamping:
        conf.insert_json5("timestamping/enabled", "true")
    delay, attempt, refusals, started = 0.1, 0, 0, time.monotonic()
    while True:
        try:
            session = zenoh.open(conf)
            if attempt:
                log.info("connected to %s after %.1f s", ", ".join(args.connect or []), time.monotonic() - started)
            return session
        except zenoh.ZError as exc:
            attempt += 1
            refused = args.secure and _router_listening(args.connect or [])
            refusals = refusals + 1 if refused else 0
            if refusals >= 2:  # the router is there and turned us away twice: credentials, not a slow start
                raise SystemExit(
                    f"hri: the router at {', '.join(args.connect or [])} refused user {args.user or 'cli'!r}: wrong "
                    f"password or unknown user. Check that {args.secure}/passwords has this user's line as the "
                    f"router has it (same secrets folder), or pass --user NAME"
                ) from None
            if attempt == 1 or attempt % 10 == 0:
                log.warning(
                    "waiting for the zenoh router at %s (%s); start it with `hri router` or pass --connect ENDPOINT",
                    ", ".join(args.connect or ["?"]),
                    str(exc).split(" at ")[0],
                )
            if stop is None:
                time.sleep(delay)
            elif stop.wait(delay):
                return None
            delay = min(delay * 2, max_delay)


def _router_listening(endpoints: list[str]) -> bool:
    """Whether a TCP/TLS endpoint accepts connections (then a failed open is a refusal, not an absent router)."""
    import socket

    for ep in endpoints:
        proto, _, addr = ep.partition("/")
        host, _, port = addr.split("#")[0].rpartition(":")
        if proto in ("tcp", "tls") and port.isdigit():
            try:
                socket.create_connection((host.strip("[]"), int(port)), 0.5).close()
                return True
            except OSError:
                continue
    return False


def client_config(
    endpoint: str, secure: str | None = None, user: str = "cli", prefix: str = DEFAULT_PREFIX
) -> zenoh.Config:
    """A client of the router at `endpoint`, no multicast scouting: what tools and tests open.
    `secure`: a secrets folder; log in as `user` (`PREFIX-user` where the folder has robot users of `prefix`)."""
    conf = zenoh.Config()
    conf.insert_json5("mode", '"client"')
    conf.insert_json5("connect/endpoints", json.dumps([endpoint]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    link_defaults(conf)
    if secure:
        add_security(conf, argparse.Namespace(mode="client", secure=secure, user=user, prefix=prefix))
    return conf


def open_client(
    endpoint: str, secure: str | None = None, user: str = "cli", prefix: str = DEFAULT_PREFIX
) -> zenoh.Session:
    init_zenoh_logging()
    return zenoh.open(client_config(endpoint, secure, user, prefix))


def live_tokens(session: zenoh.Session, keys: Keys, service: str = "*", timeout: float = 1.0) -> list[tuple[str, str]]:
    """(service, instance) of every liveliness token `hri/alive/{service}/*` present on the router."""
    found = []
    for reply in session.liveliness().get(keys.alive(service, "*"), timeout=timeout):
        if reply.ok is not None:
            parsed = keys.parse_alive(str(reply.ok.key_expr))
            if parsed:
                found.append(parsed)
    return found


def declare_recovering_publisher(session: zenoh.Session, key: str, **qos) -> "zenoh.ext.AdvancedPublisher":
    """A publisher whose samples a recovering subscriber gets even if it was cut off when they were sent: the
    last RECOVERY_CACHE stay in a cache, a heartbeat announces the last sequence number. Plain subscribers
    receive the same samples on the same key. The session needs timestamping (open_session(timestamping=True))."""
    from zenoh import ext

    return ext.declare_advanced_publisher(
        session,
        key,
        cache=ext.CacheConfig(max_samples=RECOVERY_CACHE),
        # the other option off, said explicitly (zenoh's type stubs have no default for it)
        sample_miss_detection=ext.MissDetectionConfig(heartbeat=HEARTBEAT_S, sporadic_heartbeat=None),
        publisher_detection=True,
        **qos,
    )


def declare_recovering_subscriber(session: zenoh.Session, key: str, handler) -> "zenoh.ext.AdvancedSubscriber":
    """Receive `key` and fetch what a recovering publisher sent while this subscriber was cut off: in order per
    publisher, each sample once. No history at start: a planner that starts late must not act on old commands."""
    from zenoh import ext

    return ext.declare_advanced_subscriber(
        session,
        key,
        handler,
        recovery=ext.RecoveryConfig(heartbeat=True, periodic_queries=None),  # None: off (the stubs want it said)
        subscriber_detection=True,
    )
