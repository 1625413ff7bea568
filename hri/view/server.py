"""The shell of `hri view`: zenoh (or a recording) in, an aiohttp server out.

HTTP API (all the page uses; handy for scripts too):
  GET  /                         the page (static/index.html)
  GET  /api/state?epoch=E&version=V&after=N
                                 the state as JSON; waits up to 10 s for a version other than V (long poll).
                                 Timeline entries after N only, unless the epoch changed (then all).
  GET  /api/frame/{cam}?after=N  the newest released JPEG of a camera once it is newer than N (long poll,
                                 204 after 10 s); headers X-Frame-N, X-Seq, X-Stamp
  POST /api/player               recording mode: {"action": "play"|"pause"|"seek", "position": seconds}

Nothing is queued per client: every answer is built from the current state when it is sent, so a slow or
closed tab costs one pending request, never a growing buffer, and never slows the zenoh callbacks.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import logging
import sys
import threading
import time
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from common.keys import Keys
from hri.view.core import ShownFrame, ViewState
from hri.view.draw import render

STATIC = Path(__file__).resolve().parent / "static"
LONG_POLL_S = 10.0
STATS_EVERY_S = 2.0


class Changes:
    """Wakes long-polling requests when the state changes; `notify` may be called from any thread."""

    def __init__(self, loop: asyncio.AbstractEventLoop):
        self.loop = loop
        self._event = asyncio.Event()
        self._scheduled = threading.Event()
        self.closed = False

    def close(self) -> None:
        """Answer every waiting request now (the server is stopping)."""
        self.closed = True
        self._event.set()

    def notify(self) -> None:
        if not self._scheduled.is_set():  # coalesce bursts: one wake-up per loop turn
            self._scheduled.set()
            self.loop.call_soon_threadsafe(self._fire)

    def _fire(self) -> None:
        self._scheduled.clear()
        event, self._event = self._event, asyncio.Event()
        event.set()

    async def wait(self, timeout: float) -> None:
        try:
            await asyncio.wait_for(self._event.wait(), timeout)
        except asyncio.TimeoutError:
            pass


def _int(request: Any, name: str, default: int = 0) -> int:
    try:
        return int(request.query.get(name, default))
    except ValueError:
        return default


async def _next_frame(state: ViewState, changes: Changes, cam: str, after: int) -> ShownFrame | None:
    """The camera's shown frame once it is not frame `after` (long poll); None when none came in time."""
    deadline = time.monotonic() + LONG_POLL_S
    while True:
        shown = state.frame(cam)
        if shown is not None and shown.n != after:
            return shown
        if time.monotonic() >= deadline or changes.closed:
            return None
        await changes.wait(deadline - time.monotonic())


def _apply_player_action(player: Any, body: dict[str, Any]) -> None:
    """play / pause / seek a recording's player (ValueError, KeyError or TypeError for a bad request)."""
    action = body["action"]
    if action == "play":
        if player.offset_s >= player.duration_s:
            player.seek(0.0)
        player.playing = True
    elif action == "pause":
        player.playing = False
    elif action == "seek":
        player.seek(float(body["position"]))
    else:
        raise ValueError(action)


def make_app(state: ViewState, mode: dict[str, Any], player: Any = None) -> Any:
    """The aiohttp application over a state; `mode` says live or recording (shown by the page)."""
    from aiohttp import web

    async def index(_request: web.Request) -> web.StreamResponse:
        return web.FileResponse(STATIC / "index.html", headers={"Cache-Control": "no-store"})

    async def api_state(request: web.Request) -> web.Response:
        changes: Changes = request.app["changes"]
        epoch, version = _int(request, "epoch"), _int(request, "version", -1)
        deadline = time.monotonic() + LONG_POLL_S
        while state.epoch == epoch and state.version == version and time.monotonic() < deadline and not changes.closed:
            await changes.wait(deadline - time.monotonic())
        after = _int(request, "after") if state.epoch == epoch else 0
        body = state.snapshot(after)
        body["mode"] = mode
        if player is not None:
            body["player"] = player.status()
        return web.Response(
            text=json.dumps(body, separators=(",", ":")),
            content_type="application/json",
            headers={"Cache-Control": "no-store"},
        )

    async def api_frame(request: web.Request) -> web.Response:
        changes: Changes = request.app["changes"]
        shown = await _next_frame(state, changes, request.match_info["cam"], _int(request, "after", -1))
        if shown is None:
            return web.Response(status=204, headers={"Cache-Control": "no-store"})
        return web.Response(
            body=shown.jpeg,
            content_type="image/jpeg",
            headers={
                "Cache-Control": "no-store",
                "X-Frame-N": str(shown.n),
                "X-Seq": str(shown.seq),
                "X-Stamp": repr(shown.stamp),
            },
        )

    async def api_depth(request: web.Request) -> web.Response:
        """The camera's latest depth frame as a colourized JPEG (the page's depth toggle); 204 without depth."""
        picture = await asyncio.get_running_loop().run_in_executor(None, state.depth_picture, request.match_info["cam"])
        if picture is None:
            return web.Response(status=204, headers={"Cache-Control": "no-store"})
        seq, stamp, jpeg = picture
        return web.Response(
            body=jpeg,
            content_type="image/jpeg",
            headers={"Cache-Control": "no-store", "X-Seq": str(seq), "X-Stamp": repr(stamp)},
        )

    async def api_player(request: web.Request) -> web.Response:
        if player is None:
            return web.json_response({"error": "not a recording: start `hri view FILE.mcap`"}, status=409)
        try:
            body = await request.json()
            with state.lock:
                _apply_player_action(player, body)
        except (ValueError, KeyError, TypeError) as exc:
            return web.json_response(
                {"error": f"bad player request ({exc}); send {{'action': 'play'|'pause'|'seek', 'position': seconds}}"},
                status=400,
            )
        request.app["changes"].notify()
        return web.json_response(player.status())

    app = web.Application()
    app.router.add_get("/", index)
    app.router.add_get("/api/state", api_state)
    app.router.add_get("/api/frame/{cam}", api_frame)
    app.router.add_get("/api/depth/{cam}", api_depth)
    app.router.add_post("/api/player", api_player)
    app.router.add_static("/static/", STATIC)
    return app


# ---------------------------------------------------------------------------
# Inputs: the live bus or a recording
# ---------------------------------------------------------------------------
class LiveInput:
    """Feeds the state from zenoh: every contract key under the prefix, liveliness, and polled stats."""

    def __init__(self, session: Any, state: ViewState, on_change: Any, log: logging.Logger):
        import zenoh

        self.session, self.state, self.on_change, self.log = session, state, on_change, log
        keys = state.keys
        audio = keys.audio("*")

        def on_sample(sample: zenoh.Sample) -> None:
            key = str(sample.key_expr)
            if sample.kind != zenoh.SampleKind.PUT or zenoh.KeyExpr(audio).intersects(key):
                return  # audio is not shown; skipping it saves decoding 50 chunks a second
            if not state.ingest(key, sample.payload.to_bytes(), time.monotonic()):
                self._log_ignored(key)
            on_change()

        def on_token(sample: zenoh.Sample) -> None:
            parsed = keys.parse_alive(str(sample.key_expr))
            if parsed:
                state.set_alive(*parsed, alive=sample.kind == zenoh.SampleKind.PUT)
                on_change()

        self._ignored_logged = 0
        self.declared = [
            session.declare_subscriber(f"{keys.prefix}/**", on_sample),
            session.liveliness().declare_subscriber(keys.alive("*", "*"), on_token, history=True),
        ]
        self.stop = threading.Event()
        self.poller = threading.Thread(target=self._poll_stats, name="view-stats", daemon=True)
        self.poller.start()

    def _log_ignored(self, key: str) -> None:
        self._ignored_logged += 1
        n = self._ignored_logged
        if n <= 5 or n % 100 == 0:
            self.log.warning("ignored an invalid sample on %s (#%d; the page lists them by key and reason)", key, n)

    def _poll_stats(self) -> None:
        from common.codec import decode
        from common.schema import InvalidSample, Stats

        while not self.stop.is_set():
            try:
                for reply in self.session.get(self.state.keys.stats("*", "*"), timeout=1.0):
                    if reply.ok is None:
                        continue
                    try:
                        self.state.set_stats(decode(reply.ok.payload.to_bytes(), Stats))
                    except InvalidSample as exc:
                        self.state.ignore(str(reply.ok.key_expr), exc.reason)
                self.on_change()
            except Exception as exc:  # the session is closing, or the router went away for a while
                if self.stop.is_set():
                    return
                self.log.debug("stats query failed: %s", exc)
            self.stop.wait(STATS_EVERY_S)

    def close(self) -> None:
        self.stop.set()
        for d in self.declared:
            try:
                d.undeclare()
            except Exception:
                pass


async def _clock(state: ViewState, changes: Changes, player: Any) -> None:
    """Releases throttled frames in live mode; moves the cursor while a recording plays."""
    last = time.monotonic()
    while True:
        await asyncio.sleep(0.02 if player is None else 0.05)
        now = time.monotonic()
        if player is None:
            if state.tick(now):
                changes.notify()
        elif player.playing:
            with state.lock:
                player.advance(now - last)
            changes.notify()
        last = now


async def serve(args: argparse.Namespace, state: ViewState, mode: dict[str, Any], player: Any, start_input: Any) -> int:
    from aiohttp import web

    loop = asyncio.get_running_loop()
    changes = Changes(loop)
    app = make_app(state, mode, player)
    app["changes"] = changes
    runner = web.AppRunner(app, access_log=None)
    await runner.setup()
    site = web.TCPSite(runner, args.host, args.port)
    try:
        await site.start()
    except OSError as exc:
        print(
            f"hri view: cannot listen on {args.host}:{args.port}: {exc.strerror or exc}; choose another "
            f"--port (0 picks a free one)",
            file=sys.stderr,
        )
        await runner.cleanup()
        return 2
    server = site._server
    assert isinstance(server, asyncio.Server)  # a TCPSite's server once started
    port = server.sockets[0].getsockname()[1]  # the real port when --port 0
    host = "127.0.0.1" if args.host in ("0.0.0.0", "") else args.host
    print(f"hri view: http://{host}:{port}/  ({mode['label']}; Ctrl-C to stop)", flush=True)
    stop = asyncio.Event()
    import signal

    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)
    feed = start_input(changes.notify)
    clock = asyncio.create_task(_clock(state, changes, player))
    try:
        await stop.wait()
    finally:
        changes.close()  # waiting long polls answer at once, so stopping takes no LONG_POLL_S
        clock.cancel()
        if feed is not None:
            feed()
        await runner.cleanup()
    return 0


# ---------------------------------------------------------------------------
# Snapshot: the annotated frame of a camera as a PNG
# ---------------------------------------------------------------------------
def annotated(state: ViewState, cam: str | None) -> tuple[str, np.ndarray] | None:
    """(camera, annotated BGR image) of `cam` (or the first camera with a frame), None if there is none."""
    with state.lock:
        cams = [c for c, s in sorted(state.cameras.items()) if s.shown is not None and (cam is None or c == cam)]
        if not cams:
            return None
        shown = state.cameras[cams[0]].shown
        assert shown is not None  # chosen above
        layers = state.overlay(cams[0])
    image = cv2.imdecode(np.frombuffer(shown.jpeg, np.uint8), cv2.IMREAD_COLOR)
    if image is None:
        return None
    return cams[0], render(image, layers)


def _write_snapshot(state: ViewState, args: argparse.Namespace, where: str) -> int:
    got = annotated(state, args.cam)
    if got is None:
        which = f"camera {args.cam!r}" if args.cam else "any camera"
        print(
            f"hri view: no frame of {which} {where}; cameras seen: {', '.join(state.cameras) or 'none'}",
            file=sys.stderr,
        )
        return 1
    cam, image = got
    if not cv2.imwrite(args.snapshot, image, [cv2.IMWRITE_PNG_COMPRESSION, 9]):  # small enough for a bug report
        print(
            f"hri view: cannot write {args.snapshot} (does the folder exist? is the extension .png?)", file=sys.stderr
        )
        return 2
    print(f"hri view: wrote {args.snapshot} (camera {cam}, {image.shape[1]}x{image.shape[0]})")
    return 0


# ---------------------------------------------------------------------------
# The command
# ---------------------------------------------------------------------------
def cmd_view(args: argparse.Namespace) -> int:
    from common.runner import setup_logging
    from common.transport import open_session, resolve

    resolve(args)
    if args.at is not None and not (args.snapshot and args.recording):
        print("hri view: --at needs --snapshot and a recording (the live bus has no past)", file=sys.stderr)
        return 2
    log = setup_logging("hri.view", args.log_level)
    state = ViewState(Keys(args.prefix), max_fps=args.max_fps)

    if args.recording:
        from hri.recording import RecordingError
        from hri.view.player import Player

        try:
            player = Player.open(args.recording, state)
        except RecordingError as exc:
            print(f"hri view: {exc}", file=sys.stderr)
            return 2
        if not player.messages:
            print(f"hri view: {args.recording} holds no msgpack samples", file=sys.stderr)
            return 1
        if args.snapshot:
            at = args.at if args.at is not None else player.end_ns / 1e9
            if at < 1e9:
                at += player.start_ns / 1e9
            with state.lock:
                player.at_stamp(at)
            return _write_snapshot(state, args, f"at or before stamp {at:.3f} in {args.recording}")
        with state.lock:
            player.seek(0.0)
        mode = {
            "live": False,
            "label": f"recording {Path(args.recording).name}",
            "file": str(Path(args.recording).name),
        }
        return asyncio.run(serve(args, state, mode, player, lambda notify: None))

    stop = threading.Event()
    session = open_session(args, log, stop)
    if session is None:
        return 0
    try:
        if args.snapshot:
            feed = LiveInput(session, state, lambda: None, log)
            try:
                deadline = time.monotonic() + args.timeout
                while time.monotonic() < deadline:
                    state.tick(time.monotonic())
                    if annotated(state, args.cam) is not None:
                        time.sleep(args.wait)  # detections, hands and a decision arrive after the frame
                        state.tick(time.monotonic(), force=True)
                        break
                    time.sleep(0.05)
            finally:
                feed.close()
            return _write_snapshot(state, args, f"within {args.timeout:g} s on {', '.join(args.connect or [])}")
        mode = {"live": True, "label": f"live, {', '.join(args.connect or ['zenoh'])}"}

        def start(notify: Any) -> Any:
            return LiveInput(session, state, notify, log).close

        return asyncio.run(serve(args, state, mode, None, start))
    finally:
        session.close()
