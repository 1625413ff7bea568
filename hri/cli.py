"""`hri`: the command line users live in — watch, publish, inspect, route."""

from __future__ import annotations

import argparse
import base64
import json
import os
import queue
import signal
import sys
import threading
import time
from typing import Any

import zenoh

from common.codec import decode, unpack
from common.keys import Keys
from common.runner import SamplePublisher, setup_logging
from common.schema import InvalidSample, Stats, make_transcript
from common.settings import add_option
from common.transport import (
    add_zenoh_arguments,
    init_zenoh_logging,
    live_tokens,
    open_session,
    resolve,
    size_router_pools,
    zenoh_config,
)

EXAMPLES = """\
examples:
  hri router                                   # the zenoh router every service connects to
  hri echo 'hri/**'                            # every sample, one JSON line each
  hri echo 'hri/fusion/**'                     # fused commands and clarification questions
  hri echo 'hri/camera/*/frame' --count 5      # five frames, then exit
  hri say "pick up the red cup"                # publish a Transcript as if it had been spoken
  hri pub hri/speech/kbd/transcript '{"mic":"kbd","start":1.0,"end":2.0,"text":"stop","confidence":1,
          "words":[],"final":true,"backend":"text"}'
  hri list                                     # live services (liveliness tokens)
  hri stats                                    # received / published / rejected counters per service
  hri up --camera data/images/tabletop --speech-input text   # router + every service, type commands
  hri record -o session.mcap 'hri/**'          # everything to MCAP until Ctrl-C (--count N / --duration S)
  hri replay session.mcap --only 'hri/speech/**' --speed 2   # back onto the bus, original timing x2
  hri export --rosbag2 session.mcap bag/        # the recording as a ROS 2 bag (ros2 bag play, Foxglove)
  hri view                                     # a web page of cameras, overlays and decisions; prints its URL
"""


def summarise(value: Any) -> Any:
    """JSON-friendly view: binary fields become '<N bytes>'."""
    if isinstance(value, (bytes, bytearray, memoryview)):
        return f"<{len(value)} bytes>"
    if isinstance(value, dict):
        return {str(k): summarise(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [summarise(v) for v in value]
    return value


def compact_persons(line: dict[str, Any]) -> dict[str, Any]:
    """A `Persons` sample on one short line: each person's nil fields left out, the box in whole pixels."""
    persons = line.get("persons")
    if not isinstance(persons, list):
        return line
    short = [
        {
            k: ([round(v) for v in value] if k == "bbox" and isinstance(value, list) else value)
            for k, value in p.items()
            if value not in (None, [], False)
        }
        for p in persons
        if isinstance(p, dict)
    ]
    return {**line, "persons": short}


def _install_stop(stop: threading.Event) -> None:
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())


def _open(args: argparse.Namespace, stop: threading.Event) -> zenoh.Session:
    log = setup_logging("hri", getattr(args, "log_level", None))
    session = open_session(args, log, stop)
    if session is None:
        sys.exit(0)
    return session


# -- router ------------------------------------------------------------------
def cmd_router(args: argparse.Namespace) -> int:
    args.mode = "router"
    args.listen = args.listen or [e for e in os.environ.get("HRI_LISTEN", "").split(",") if e] or ["tcp/127.0.0.1:7447"]
    log = setup_logging("hri.router", args.log_level)
    init_zenoh_logging()
    pools = size_router_pools()
    conf = zenoh_config(args)
    # before the port opens: a client that sees the port may stop the router at once, and must get exit 0
    stop = threading.Event()
    _install_stop(stop)
    try:
        session = zenoh.open(conf)
    except zenoh.ZError as exc:
        log.error(
            "cannot start the router on %s: %s (is another router already listening there?)",
            ", ".join(args.listen),
            str(exc).split(" at ")[0],
        )
        return 1
    log.info("zenoh router listening on %s (zid %s, ZENOH_RUNTIME %s)", ", ".join(args.listen), session.zid(), pools)
    if args.secure:
        from common.security import read_secrets

        sec = read_secrets(args.secure)
        log.info(
            "secured: %d users must log in (%s), access rules from %s/users.json; everything else is denied",
            len(sec.users),
            ", ".join(sorted(sec.users)),
            args.secure,
        )
    else:
        log.warning(
            "not secured: any client that reaches %s may publish anything, commands included "
            "(see `hri secure init --help`)",
            ", ".join(args.listen),
        )
    stop.wait()
    session.close()
    log.info("router stopped")
    return 0


# -- echo --------------------------------------------------------------------
def cmd_echo(args: argparse.Namespace) -> int:
    stop = threading.Event()
    _install_stop(stop)
    session = _open(args, stop)
    keys = Keys(args.prefix)
    inbox: queue.Queue[tuple[str, bytes]] = queue.Queue()
    sub = session.declare_subscriber(args.keyexpr, lambda s: inbox.put((str(s.key_expr), s.payload.to_bytes())))
    deadline = time.monotonic() + args.timeout if args.timeout else None
    printed, invalid = 0, 0
    try:
        while not stop.is_set() and (args.count is None or printed < args.count):
            wait = 0.2 if deadline is None else min(0.2, deadline - time.monotonic())
            if wait <= 0:
                break
            try:
                key, payload = inbox.get(timeout=wait)
            except queue.Empty:
                continue
            schema = keys.schema_for(key)
            try:
                if args.raw or schema is None:
                    body = unpack(payload, 64 << 20)
                else:
                    body = decode(payload, schema).to_dict()
            except InvalidSample as exc:
                invalid += 1
                print(f"hri echo: invalid sample on {key}: {exc}", file=sys.stderr, flush=True)
                continue
            line = {"key": key, **(body if isinstance(body, dict) else {"value": body})}
            print(json.dumps(summarise(compact_persons(line)), separators=(",", ":")), flush=True)
            printed += 1
    finally:
        sub.undeclare()
        session.close()
    if args.count is not None and printed < args.count:
        print(
            f"hri echo: timed out after {args.timeout} s with {printed}/{args.count} samples on "
            f"{args.keyexpr!r}; is the publisher running and connected to the same router?",
            file=sys.stderr,
        )
        return 1
    return 0


# -- pub / say ---------------------------------------------------------------
def _from_json(value: Any) -> Any:
    """{"$b64": "..."} stands for a binary field in JSON."""
    if isinstance(value, dict):
        if set(value) == {"$b64"}:
            return base64.b64decode(value["$b64"])
        return {k: _from_json(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_from_json(v) for v in value]
    return value


def _publish_once(args: argparse.Namespace, key: str, sample: Any) -> int:
    if args.secure:  # the router would drop it without a word: say so here
        from common.security import SecurityError, may_publish, read_secrets

        user = args.user or "cli"
        try:
            sec = read_secrets(args.secure)
        except SecurityError as exc:
            print(f"hri {args.command}: {exc}", file=sys.stderr)
            return 2
        if not may_publish(sec, user, key, args.prefix):
            print(
                f"hri {args.command}: user {user!r} (roles: {', '.join(sec.users.get(user, [])) or 'none'}) may not "
                f"publish on {key}; the router would drop it. Use --user with a role that may (e.g. a user with "
                f"the keyboard role for hri say: `hri secure init {args.secure} --user operator:reader,keyboard`)",
                file=sys.stderr,
            )
            return 2
    stop = threading.Event()
    session = _open(args, stop)
    pub = SamplePublisher(session, key, lossless=True)
    try:
        pub.put(sample)  # validates on the way out
        time.sleep(0.1)  # let the router forward it before the session goes away
        return 0
    except InvalidSample as exc:
        print(f"hri {args.command}: not a valid {type(sample).__name__}: {exc}", file=sys.stderr)
        return 2
    finally:
        pub.undeclare()
        session.close()


def cmd_pub(args: argparse.Namespace) -> int:
    resolve(args)
    schema = Keys(args.prefix).schema_for(args.key)
    if schema is None:
        print(f"hri pub: {args.key!r} is not a key of the wire contract (see docs/wire.md)", file=sys.stderr)
        return 2
    try:
        body = _from_json(json.loads(args.json))
    except json.JSONDecodeError as exc:
        print(f"hri pub: the sample is not valid JSON: {exc}", file=sys.stderr)
        return 2
    if not isinstance(body, dict):
        print("hri pub: the sample must be a JSON object", file=sys.stderr)
        return 2
    body.setdefault("v", 1)
    body.setdefault("stamp", time.time())
    body.setdefault("source", f"cli/{os.getpid()}")
    try:
        sample = schema.from_dict(body)
    except InvalidSample as exc:
        print(f"hri pub: not a valid {schema.__name__}: {exc}", file=sys.stderr)
        return 2
    return _publish_once(args, args.key, sample)


def cmd_say(args: argparse.Namespace) -> int:
    resolve(args)
    text = " ".join(args.text).strip()
    if not text:
        print("hri say: nothing to say", file=sys.stderr)
        return 2
    sample = make_transcript(
        text, mic=args.mic, end=time.time(), confidence=args.confidence, source=f"cli/{os.getpid()}"
    )
    return _publish_once(args, Keys(args.prefix).transcript(args.mic), sample)


# -- list / stats --------------------------------------------------------------
def cmd_list(args: argparse.Namespace) -> int:
    stop = threading.Event()
    session = _open(args, stop)
    keys = Keys(args.prefix)
    found = live_tokens(session, keys, timeout=args.timeout)
    session.close()
    for service, instance in sorted(found):
        print(f"{service:10s} {instance}")
    if not found:
        print("no live services (is the router running, and are the services connected to it?)", file=sys.stderr)
    return 0


def cmd_stats(args: argparse.Namespace) -> int:
    stop = threading.Event()
    session = _open(args, stop)
    keys = Keys(args.prefix)
    rows = []
    for reply in session.get(keys.stats(args.service or "*", "*"), timeout=args.timeout):
        if reply.ok is None:
            continue
        try:
            rows.append(decode(reply.ok.payload.to_bytes(), Stats))
        except InvalidSample as exc:
            print(f"hri stats: bad reply on {reply.ok.key_expr}: {exc}", file=sys.stderr)
    session.close()
    for st in sorted(rows, key=lambda s: (s.service, s.instance)):
        print(json.dumps(st.to_dict(), separators=(",", ":")))
    if not rows:
        print("no service answered (is anything running?)", file=sys.stderr)
    return 0


# -- secure --------------------------------------------------------------------
def cmd_secure_init(args: argparse.Namespace) -> int:
    from common.security import SecurityError, init_secrets, make_tls

    extra: dict[str, list[str]] = {}
    for spec in args.user or []:
        name, sep, roles = spec.partition(":")
        if not sep or not name or not roles:
            print(f"hri secure init: --user takes NAME:ROLE[,ROLE...], got {spec!r}", file=sys.stderr)
            return 2
        extra[name] = [r for r in roles.split(",") if r]
    try:
        sec = init_secrets(args.folder, extra, robot=args.robot)
        certs = make_tls(sec.folder, args.host) if args.tls else []
    except SecurityError as exc:
        print(f"hri secure init: {exc}", file=sys.stderr)
        return 2
    for user, roles in sorted(sec.users.items()):
        print(f"{user:10s} {', '.join(roles)}")
    for cert in certs:
        print(f"wrote {cert}")
    if certs:
        print("TLS: listen and connect on tls/HOST:PORT endpoints (e.g. --listen tls/0.0.0.0:7447)")
    print(
        f"secrets in {sec.folder} (passwords: {sec.passwords_file}, mode 0600). Now:\n"
        f"  hri router --secure {sec.folder}\n  hri up --secure {sec.folder} ...\n"
        f"  hri echo 'hri/**' --secure {sec.folder}           # as user cli, read-only"
    )
    return 0


# -- entry point ---------------------------------------------------------------
def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="hri",
        description="hri-fusion command line: route, watch, publish and inspect samples.",
        epilog=EXAMPLES,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    def command(name: str, help_: str, examples: str = "") -> argparse.ArgumentParser:
        p = sub.add_parser(
            name, help=help_, description=help_, epilog=examples, formatter_class=argparse.RawDescriptionHelpFormatter
        )
        p.add_argument("--log-level", default=None, help="DEBUG, INFO, WARNING … (env HRI_LOG_LEVEL)")
        add_zenoh_arguments(p)
        return p

    p = command(
        "router",
        "run the zenoh router (listens on tcp/127.0.0.1:7447 unless --listen / HRI_LISTEN)",
        "example:\n  hri router --listen tcp/0.0.0.0:7447",
    )
    p.set_defaults(func=cmd_router)

    p = command(
        "echo",
        "print samples on a key expression as JSON lines (binary fields as <N bytes>)",
        "examples:\n  hri echo 'hri/**'\n  hri echo 'hri/vision/*/objects' --count 10 --timeout 5",
    )
    p.add_argument("keyexpr", help="zenoh key expression, e.g. 'hri/**'")
    p.add_argument("--raw", action="store_true", help="print the msgpack map as is, without contract validation")
    add_option(
        p,
        "--count",
        None,
        "exit 0 after N samples (1 if the timeout comes first)",
        kind=int,
        at_least=1,
        metavar="N",
        default_text="never",
    )
    add_option(p, "--timeout", None, "give up after S seconds", kind=float, above=0, metavar="S", default_text="never")
    p.set_defaults(func=cmd_echo)

    p = command(
        "pub",
        "validate a JSON sample against the contract and publish it once",
        'example:\n  hri pub hri/speech/kbd/transcript \'{"mic":"kbd","start":1,"end":2,"text":'
        '"stop","confidence":1,"words":[],"final":true,"backend":"text"}\'\n'
        'v, stamp (now) and source are filled in when absent; binary fields are {"$b64": "..."}.',
    )
    p.add_argument("key", help="a concrete key of the contract, e.g. hri/speech/kbd/transcript")
    p.add_argument("json", help="the sample as a JSON object")
    p.set_defaults(func=cmd_pub)

    p = command(
        "say",
        "publish a final Transcript as if the words had just been spoken",
        'examples:\n  hri say pick up the red cup\n  hri say --confidence 0.4 "bring me that"',
    )
    p.add_argument("text", nargs="+", help="the utterance")
    p.add_argument("--mic", default="kbd", help="microphone id in the key and sample (default kbd)")
    add_option(p, "--confidence", 1.0, "recogniser confidence", at_least=0, at_most=1, metavar="P")
    p.set_defaults(func=cmd_say)

    p = command("list", "list live services from their liveliness tokens", "example:\n  hri list")
    add_option(p, "--timeout", 1.0, "seconds to wait for answers", above=0, metavar="S")
    p.set_defaults(func=cmd_list)

    p = command(
        "stats",
        "print each service's counters (received, published, rejected by reason, skipped)",
        "examples:\n  hri stats\n  hri stats --service vision",
    )
    p.add_argument("--service", default=None, help="only this service")
    add_option(p, "--timeout", 1.0, "seconds to wait for answers", above=0, metavar="S")
    p.set_defaults(func=cmd_stats)

    p = sub.add_parser(
        "secure",
        help="secured robots: create the users, passwords and access rules",
        description="Create or extend a secrets folder: a random password per user, and which "
        "roles each user has (docs/security.md).",
    )
    secure_sub = p.add_subparsers(dest="secure_command", required=True, metavar="ACTION")
    p = secure_sub.add_parser(
        "init",
        help="create DIR/passwords and DIR/users.json (existing passwords kept)",
        epilog="examples:\n  hri secure init ~/.hri/robot1\n"
        "  hri secure init ~/.hri/robot1 --user operator:reader,keyboard\n"
        "  hri secure init ~/.hri/robot1 --tls --host robot1.local   # + TLS\n"
        "roles: camera mic vision gesture speech fusion reader keyboard replay",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("folder", help="the secrets folder (created mode 0700)")
    p.add_argument(
        "--user",
        action="append",
        metavar="NAME:ROLE[,ROLE]",
        help="add a user with these roles, repeatable (the services and a read-only cli user are always there)",
    )
    p.add_argument(
        "--robot",
        default=None,
        metavar="PREFIX",
        help="several robots on one router: add this robot's own users (PREFIX-camera, …, PREFIX-cli), "
        "allowed only under keys PREFIX/**; run once per robot on the router's folder, and give "
        "each robot's machines its lines of the passwords file (docs/foundation.md, Across machines)",
    )
    p.add_argument(
        "--tls",
        action="store_true",
        help="also make a private CA and a router certificate (openssl) in DIR/tls/; then use tls/ endpoints",
    )
    p.add_argument(
        "--host",
        action="append",
        default=[],
        metavar="NAME_OR_IP",
        help="with --tls: a name or address the router is reached at, repeatable (default localhost, "
        "127.0.0.1 and this machine's name)",
    )
    p.set_defaults(func=cmd_secure_init)

    from hri import launcher

    p = command("up", "start the router and every service as one group; Ctrl-C stops them all", launcher.UP_EXAMPLES)
    launcher.add_up_arguments(p)
    p.set_defaults(func=launcher.cmd_up)
    from hri import recording  # imports mcap only when record/replay actually run

    recording.add_record_arguments(
        command(
            "record",
            "write every sample on key expressions to an MCAP file (Ctrl-C finishes it)",
            recording.RECORD_EXAMPLES,
        )
    )
    recording.add_replay_arguments(
        command("replay", "republish a recorded MCAP session with its original timing", recording.REPLAY_EXAMPLES)
    )
    from hri.viewers import live  # foxglove-sdk is imported only when `hri foxglove` runs

    live.add_foxglove_arguments(
        command("foxglove", "serve the live stack to Foxglove (WebSocket protocol)", live.FOXGLOVE_EXAMPLES)
    )
    from hri.viewers import rerun_log  # rerun-sdk is imported only when `hri rerun` runs

    rerun_log.add_rerun_arguments(
        command(
            "rerun",
            "log the live stack (or a recording) to Rerun: a served web viewer, a spawned one, or an .rrd",
            rerun_log.RERUN_EXAMPLES,
        )
    )
    from hri import rosbag2  # rosbags is imported only when an export runs

    rosbag2.add_export_arguments(
        command("export", "convert a recording: --rosbag2 writes a ROS 2 bag (MCAP, CDR)", rosbag2.EXPORT_EXAMPLES)
    )
    from hri.view import command as view  # aiohttp and OpenCV are imported only when `hri view` runs

    view.add_view_arguments(
        command(
            "view",
            "a live web page of cameras, overlays, decisions and services (or of a recording)",
            view.VIEW_EXAMPLES,
        )
    )
    return parser


def main(argv: list[str] | None = None) -> None:
    args = build_parser().parse_args(argv)
    code = args.func(args)
    sys.stdout.flush()
    sys.exit(code)


if __name__ == "__main__":
    main()
