"""`hri foxglove`: the running stack over the Foxglove WebSocket protocol (foxglove-sdk), live.

The same channels as a recording's viewer channels (hri/viewers/foxglove_msgs.py), plus every service's Stats
as JSON on `/<prefix>/stats/<service>/<instance>` every 2 s. Open Foxglove (app or web), "Open connection",
Foxglove WebSocket, ws://HOST:PORT; docs/foxglove-layout.json is a ready layout (docs/viewers.md).
"""

from __future__ import annotations

import argparse
import sys
import threading
from typing import Any

from common.keys import Keys
from common.schema import Clarification, FusedCommand, Sample
from common.settings import add_option
from hri.viewers.foxglove_msgs import (
    VIEWER_METADATA,
    FoxgloveConverter,
    ServicesState,
    ViewerMessage,
    available,
    json_schema_of,
    protobuf_schema,
)

FOXGLOVE_EXAMPLES = """\
examples:
  hri foxglove                           # ws://127.0.0.1:8765, then Foxglove: Open connection -> Foxglove WebSocket
  hri foxglove --host 0.0.0.0 --port 8765   # reachable from other machines
  hri foxglove --no-audio                # leave the microphones' audio out
A recording needs no server: open the .mcap of `hri record` in Foxglove directly.
"""


FIRST_MESSAGE_DELAY_S = 0.3


def fixed_channels(keys: Keys, converter: FoxgloveConverter) -> list[ViewerMessage]:
    """Placeholders (never logged) of the channels whose topics do not depend on a camera or microphone name."""

    def empty(topic: str, schema: Any, encoding: str) -> ViewerMessage:
        return ViewerMessage(topic, schema, encoding, b"", 0)

    return [
        empty(converter.log_topic, protobuf_schema("Log"), "protobuf"),
        empty(converter.tf_topic, protobuf_schema("FrameTransform"), "protobuf"),
        empty(converter.services_topic, json_schema_of(ServicesState), "json"),
        empty("/" + keys.command(), json_schema_of(FusedCommand), "json"),
        empty("/" + keys.clarification(), json_schema_of(Clarification), "json"),
    ]


class FoxgloveBridge:
    """Sink of a LiveFeed: converts each sample and logs it on its (lazily created) foxglove channel."""

    def __init__(self, keys: Keys, context: Any = None):
        import foxglove

        self._foxglove = foxglove
        self.converter = FoxgloveConverter(keys)
        self.context = context
        self.channels: dict[tuple[str, str], Any] = {}
        self.lock = threading.Lock()  # the feed's worker and the stats poller both log
        for m in fixed_channels(keys, self.converter):
            self.channel(m)  # advertised from the start: a client is subscribed before the first line or command

    def channel(self, m: ViewerMessage) -> tuple[Any, bool]:
        """The channel of a message's topic and schema, and whether it was created just now."""
        channel = self.channels.get((m.topic, m.schema.name))
        created = channel is None
        if channel is None:
            fg = self._foxglove
            schema = fg.Schema(name=m.schema.name, encoding=m.schema.encoding, data=m.schema.data)
            channel = self.channels[(m.topic, m.schema.name)] = fg.Channel(
                m.topic,
                schema=schema,
                message_encoding=m.message_encoding,
                context=self.context,
                metadata={VIEWER_METADATA: "true"},
            )
        return channel, created

    def __call__(self, key: str, sample: Sample, receive_ns: int) -> None:
        with self.lock:
            for m in self.converter.convert(key, sample):
                channel, created = self.channel(m)
                if created:
                    # a client subscribes only once the channel is advertised: the first message of a new
                    # channel (the first command, the first words) waits for that round trip instead of being lost
                    timer = threading.Timer(FIRST_MESSAGE_DELAY_S, channel.log, (m.data,), {"log_time": receive_ns})
                    timer.daemon = True
                    timer.start()
                else:
                    channel.log(m.data, log_time=receive_ns)


def add_foxglove_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--host", default="127.0.0.1", help="address to serve on (default 127.0.0.1; 0.0.0.0 for others)")
    add_option(p, "--port", 8765, "port (0 picks a free one)", at_least=0, at_most=65535)
    p.add_argument("--no-audio", dest="audio", action="store_false", help="do not forward the microphones' audio")
    p.set_defaults(func=cmd_foxglove)


def cmd_foxglove(args: argparse.Namespace) -> int:
    if not available():
        print("hri foxglove needs foxglove-sdk: pip install 'hri-fusion[foxglove]'", file=sys.stderr)
        return 2
    import foxglove

    from common.runner import setup_logging
    from common.transport import open_session, resolve
    from hri.recording import _stop_on_signals
    from hri.viewers.feed import LiveFeed

    resolve(args)
    keys = Keys(args.prefix)
    log = setup_logging("hri.foxglove", args.log_level)
    try:
        server = foxglove.start_server(name="hri-fusion", host=args.host, port=args.port)
    except Exception as exc:  # the SDK raises its own error type for a port in use
        print(f"hri foxglove: cannot listen on {args.host}:{args.port}: {exc}", file=sys.stderr)
        return 2
    stop = threading.Event()
    _stop_on_signals(stop)
    session = open_session(args, log, stop)
    if session is None:
        server.stop()
        return 0
    feed = LiveFeed(session, keys, FoxgloveBridge(keys), log, skip=() if args.audio else (keys.audio("*"),))
    # printed once subscribed: from here on nothing the stack publishes is missed
    print(f"hri foxglove: ws://{args.host}:{server.port}  (Foxglove: Open connection; Ctrl-C to stop)", flush=True)
    stop.wait()
    feed.close()
    session.close()
    server.stop()
    c = feed.counts
    invalid = sum(c.invalid.values())
    print(
        f"hri foxglove: {c.shown} samples shown, {invalid} invalid; viewer behind: {c.skipped} stream samples "
        f"skipped, {c.dropped} events dropped",
        file=sys.stderr,
    )
    return 0
