"""`hri rerun`: the live stack (or a recording) logged to Rerun.

Entity tree (the camera's optical frame is x right, y down, z forward; `world` is z up):
- `world/<cam>`: the camera's pose (Transform3D, optical -> world);
- `world/<cam>/image`: Pinhole (from the frame's CameraInfo) + the frame as an EncodedImage (JPEG/PNG as sent;
  raw bgr8 frames are JPEG-encoded once: logging an encoded image costs Rerun a sixth of a raw one);
  `world/<cam>/depth` (Pinhole + DepthImage, metres; a point cloud in 3-D),
  `.../image/objects` (Boxes2D, labels, the object's colour),
  `.../image/hands` + `.../image/rays` (LineStrips2D), `.../image/bodies`, `.../image/faces`,
  `.../image/persons` (Boxes2D, the speaker magenta and labelled "speaking");
- `world/<cam>/objects` (Boxes3D, metres), `world/<cam>/pointing` (Arrows3D) and `.../pointing/hits`
  (Points3D: the floor/table hit), `world/<cam>/persons` (Points3D, the speaker marked);
- `log/speech`, `log/gestures`, `log/commands` (TextLog); `latency/<service>` (Scalars: receive time minus
  the sample's source stamp, ms);
- timeline `stamp`: the samples' source time.

The mapping (`items`) is pure (archetypes out, no I/O); `cmd_rerun` is the shell. RERUN_ANALYTICS=0 is set by
the command (Rerun's usage analytics are off unless you set RERUN_ANALYTICS=1 yourself).
"""

from __future__ import annotations

import argparse
import os
import sys
import threading
from typing import Any, Iterator

import numpy as np

from common.keys import Keys
from common.schema import (
    Bodies,
    Clarification,
    DepthFrame,
    Detections,
    Faces,
    Frame,
    FusedCommand,
    GestureEvent,
    Hands,
    Persons,
    Ray,
    Sample,
    Stats,
    Transcript,
)
from common.settings import add_option
from hri.viewers.foxglove_msgs import (
    BODY_CONNECTIONS,
    BODY_RGBA,
    FACE_RGBA,
    HAND_CONNECTIONS,
    HAND_RGBA,
    OPTICAL_IN_WORLD,
    PERSON_RGBA,
    RAY_LENGTH_M,
    RAY_LENGTH_PX,
    RAY_RGBA,
    SPEAKER_RGBA,
    VISIBLE,
    object_label,
    object_rgba,
    speaking_person,
)

Item = tuple[str, Any, bool]  # entity path, archetype, static

RERUN_EXAMPLES = """\
examples:
  hri rerun                                  # the live stack to a web viewer served here (URL printed)
  hri rerun --spawn                          # the live stack to a Rerun viewer app started here
  hri rerun session.mcap --save session.rrd  # a recording to an .rrd file (then: rerun session.rrd)
  hri rerun session.mcap                     # a recording to the served web viewer
  hri rerun --save live.rrd --duration 60    # one minute of the live stack to a file
Rerun's usage analytics are disabled (RERUN_ANALYTICS=0) unless RERUN_ANALYTICS is set in the environment.
"""


def _rr() -> Any:
    os.environ.setdefault("RERUN_ANALYTICS", "0")  # no usage analytics unless the user asked for them
    try:
        import rerun as rr
    except ImportError:
        raise SystemExit(
            "hri rerun needs rerun-sdk (a ~170 MB wheel, not installed by default): "
            "pip install 'hri-fusion[rerun]' (or -c constraints.txt 'rerun-sdk==0.41.0')"
        ) from None
    return rr


def rgba8(rgba: tuple[float, float, float, float]) -> tuple[int, int, int, int]:
    r, g, b, a = rgba
    return (int(r * 255), int(g * 255), int(b * 255), int(a * 255))


def jpeg_of(frame: Frame) -> tuple[bytes, str]:
    """The frame as encoded image bytes and media type (JPEG/PNG passed through, bgr8 encoded as JPEG)."""
    if frame.encoding in ("jpeg", "png"):
        return frame.data, f"image/{frame.encoding}"
    import cv2

    img = np.frombuffer(frame.data, np.uint8).reshape(frame.height, frame.width, 3)
    ok, buf = cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, 85])
    if not ok:
        raise ValueError("OpenCV could not encode the frame as JPEG")
    return buf.tobytes(), "image/jpeg"


def ray_strip(ray: Ray) -> list[list[float]]:
    (ox, oy), (dx, dy) = ray.origin, ray.direction
    return [[ox, oy], [ox + dx * RAY_LENGTH_PX, oy + dy * RAY_LENGTH_PX]]


class RerunMapper:
    """Contract samples -> (entity path, Rerun archetype, static) items."""

    def __init__(self) -> None:
        self.rr = _rr()
        self.posed: set[str] = set()  # cameras whose pose was logged

    def items(self, key: str, sample: Sample, receive_ns: int) -> list[Item]:
        handler = getattr(self, "_" + type(sample).__name__, None)
        out: list[Item] = list(handler(sample)) if handler is not None else []
        latency_ms = (receive_ns / 1e9 - sample.stamp) * 1000
        if not isinstance(sample, Stats):
            out.append((f"latency/{sample.source.split('/')[0]}", self.rr.Scalars(latency_ms), False))
        return out

    def _camera(self, cam: str) -> Iterator[Item]:
        if cam not in self.posed:
            self.posed.add(cam)
            yield "world", self.rr.ViewCoordinates.RIGHT_HAND_Z_UP, True
            yield f"world/{cam}", self.rr.Transform3D(quaternion=OPTICAL_IN_WORLD), True

    def _Frame(self, f: Frame) -> Iterator[Item]:
        rr = self.rr
        yield from self._camera(f.cam)
        if f.camera_info is not None:
            k = np.asarray(f.camera_info.k, float).reshape(3, 3)
            pinhole = rr.Pinhole(image_from_camera=k, resolution=[f.width, f.height], camera_xyz=rr.ViewCoordinates.RDF)
            yield f"world/{f.cam}/image", pinhole, False
        data, media = jpeg_of(f)
        yield f"world/{f.cam}/image", rr.EncodedImage(contents=data, media_type=media), False

    def _DepthFrame(self, d: DepthFrame) -> Iterator[Item]:
        from common.depth import depth_metres

        rr = self.rr
        yield from self._camera(d.cam)
        k = np.asarray(d.camera_info.k, float).reshape(3, 3)
        pinhole = rr.Pinhole(image_from_camera=k, resolution=[d.width, d.height], camera_xyz=rr.ViewCoordinates.RDF)
        yield f"world/{d.cam}/depth", pinhole, False  # a view of its own: over the colour image it would hide it
        yield f"world/{d.cam}/depth", rr.DepthImage(depth_metres(d), meter=1.0), False

    def _Detections(self, d: Detections) -> Iterator[Item]:
        rr = self.rr
        labels = [f"{o.id} {object_label(o.label, o.color, o.score, o.position)}" for o in d.objects]
        colours = [rgba8(object_rgba(o.color)) for o in d.objects]
        yield (
            f"world/{d.cam}/image/objects",
            rr.Boxes2D(
                array=[o.bbox for o in d.objects], array_format=rr.Box2DFormat.XYWH, labels=labels, colors=colours
            ),
            False,
        )
        placed = [(o, lab, c) for o, lab, c in zip(d.objects, labels, colours) if o.position is not None]
        yield (
            f"world/{d.cam}/objects",
            rr.Boxes3D(
                centers=[o.position for o, _, _ in placed],
                sizes=[o.extent or [0.05, 0.05, 0.05] for o, _, _ in placed],
                labels=[lab for _, lab, _ in placed],
                colors=[c for _, _, c in placed],
            ),
            False,
        )

    def _Hands(self, h: Hands) -> Iterator[Item]:
        rr = self.rr
        strips = [[hand.landmarks[i], hand.landmarks[j]] for hand in h.hands for i, j in HAND_CONNECTIONS]
        yield f"world/{h.cam}/image/hands", rr.LineStrips2D(strips, colors=rgba8(HAND_RGBA)), False
        rays = [hand.ray for hand in h.hands]
        yield from self._rays(h.cam, rays)

    def _rays(self, cam: str, rays: list[Ray | None]) -> Iterator[Item]:
        rr = self.rr
        present = [r for r in rays if r is not None]
        yield f"world/{cam}/image/rays", rr.LineStrips2D([ray_strip(r) for r in present], colors=rgba8(RAY_RGBA)), False
        r3 = [r.ray3d for r in present if r.ray3d is not None]
        lengths = [
            float(np.linalg.norm(np.subtract(r.hit, r.origin))) if r.hit is not None else RAY_LENGTH_M for r in r3
        ]
        vectors = [np.asarray(r.direction) * length for r, length in zip(r3, lengths)]
        yield (
            f"world/{cam}/pointing",
            rr.Arrows3D(origins=[r.origin for r in r3], vectors=vectors, colors=rgba8(RAY_RGBA)),
            False,
        )
        hits = [r.hit for r in r3 if r.hit is not None]
        yield f"world/{cam}/pointing/hits", rr.Points3D(hits, radii=0.03, colors=rgba8(RAY_RGBA)), False

    def _Bodies(self, b: Bodies) -> Iterator[Item]:
        strips = [
            [body.landmarks[i], body.landmarks[j]]
            for body in b.bodies
            for i, j in BODY_CONNECTIONS
            if min(body.visibility[i], body.visibility[j]) >= VISIBLE
        ]
        yield f"world/{b.cam}/image/bodies", self.rr.LineStrips2D(strips, colors=rgba8(BODY_RGBA)), False
        yield from self._rays(b.cam, [r for body in b.bodies for r in (body.left_ray, body.right_ray)])

    def _Faces(self, f: Faces) -> Iterator[Item]:
        rr = self.rr
        boxes = rr.Boxes2D(
            array=[x.bbox for x in f.faces],
            array_format=rr.Box2DFormat.XYWH,
            labels=[x.id for x in f.faces],
            colors=rgba8(FACE_RGBA),
        )
        yield f"world/{f.cam}/image/faces", boxes, False

    def _Persons(self, p: Persons) -> Iterator[Item]:
        rr = self.rr
        speaker = speaking_person(p)
        labels = [x.id + (" speaking" if x.id == speaker else "") for x in p.persons]
        colours = [rgba8(SPEAKER_RGBA if x.id == speaker else PERSON_RGBA) for x in p.persons]
        boxes = rr.Boxes2D(
            array=[x.bbox for x in p.persons], array_format=rr.Box2DFormat.XYWH, labels=labels, colors=colours
        )
        yield f"world/{p.cam}/image/persons", boxes, False
        placed = [(x.position, lab, c) for x, lab, c in zip(p.persons, labels, colours) if x.position is not None]
        points = rr.Points3D(
            [pos for pos, _, _ in placed],
            radii=0.12,
            labels=[lab for _, lab, _ in placed],
            colors=[c for _, _, c in placed],
        )
        yield f"world/{p.cam}/persons", points, False

    def _GestureEvent(self, e: GestureEvent) -> Iterator[Item]:
        text = f"{e.gesture} {e.phase} ({e.hand} hand, {e.score:.2f}, {e.cam})"
        yield "log/gestures", self.rr.TextLog(text, level="INFO"), False
        if e.ray is not None:
            yield from self._rays(e.cam, [e.ray])

    def _Transcript(self, t: Transcript) -> Iterator[Item]:
        level = "INFO" if t.final else "DEBUG"
        yield "log/speech", self.rr.TextLog(f'"{t.text}" ({t.confidence:.2f}, {t.mic})', level=level), False

    def _FusedCommand(self, c: FusedCommand) -> Iterator[Item]:
        target = f" -> {c.target.id} {c.target.color or ''} {c.target.label}" if c.target else ""
        who = f" [{c.speaker.person}]" if c.speaker and c.speaker.person else ""
        text = f"{c.intent}{target} ({c.confidence:.2f}){who}: {c.explanation}"
        yield "log/commands", self.rr.TextLog(text, level="INFO"), False

    def _Clarification(self, q: Clarification) -> Iterator[Item]:
        yield "log/commands", self.rr.TextLog(f"question ({q.reason}): {q.question}", level="WARN"), False


def blueprint(cams: list[str], without_intrinsics: set[str]) -> Any:
    """The layout: each camera's image with its overlays (left, large); the 3-D scene, the text logs and the
    latencies (right); side panels collapsed. An image without intrinsics cannot be placed in 3-D: left out."""
    import rerun.blueprint as rrb

    images = [rrb.Spatial2DView(origin=f"world/{cam}/image", name=cam) for cam in cams]
    scene = ["+ /world/**"] + [f"- /world/{cam}/image/**" for cam in sorted(without_intrinsics)]
    right = rrb.Vertical(
        rrb.Spatial3DView(origin="world", name="scene (metres)", contents=scene),
        rrb.TextLogView(origin="log", name="speech, gestures, commands"),
        rrb.TimeSeriesView(origin="latency", name="latency (ms)"),
    )
    return rrb.Blueprint(rrb.Horizontal(rrb.Vertical(*images), right, column_shares=[3, 2]), collapse_panels=True)


class RerunSink:
    """Sink of a LiveFeed (or a recording): maps each sample and logs it on the `stamp` timeline; a new
    camera sends a layout with a view of its own."""

    def __init__(self, recording: Any):
        self.mapper = RerunMapper()
        self.recording = recording
        self.lock = threading.Lock()
        self.cams: list[str] = []
        self.without_intrinsics: set[str] = set()

    def __call__(self, key: str, sample: Sample, receive_ns: int) -> None:
        rr = self.mapper.rr
        with self.lock:
            if isinstance(sample, Frame) and sample.cam not in self.cams:
                self.cams.append(sample.cam)
                if sample.camera_info is None:
                    self.without_intrinsics.add(sample.cam)
                rr.send_blueprint(blueprint(self.cams, self.without_intrinsics), recording=self.recording)
            items = self.mapper.items(key, sample, receive_ns)
            rr.set_time("stamp", timestamp=sample.stamp, recording=self.recording)
            for path, archetype, static in items:
                rr.log(path, archetype, static=static, recording=self.recording)


# ---------------------------------------------------------------------------
# Shell
# ---------------------------------------------------------------------------
def add_rerun_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("recording", nargs="?", default=None, help="an .mcap from `hri record` instead of the live stack")
    out = p.add_mutually_exclusive_group()
    out.add_argument("--save", metavar="OUT.rrd", default=None, help="write an .rrd file instead of serving a viewer")
    out.add_argument("--spawn", action="store_true", help="start a Rerun viewer app here and log to it")
    add_option(p, "--web-port", 9090, "port of the served web viewer (0 picks a free one)", at_least=0, at_most=65535)
    add_option(p, "--grpc-port", 9876, "port of the served data (gRPC proxy)", at_least=0, at_most=65535)
    add_option(
        p, "--duration", None, "stop after S seconds (live)", kind=float, above=0, metavar="S", default_text="never"
    )
    p.set_defaults(func=cmd_rerun)


def _free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port: int = s.getsockname()[1]
        return port


def _open_output(args: argparse.Namespace, rr: Any, rec: Any) -> None:
    """Where the logged data goes: a file, a spawned viewer, or a served web viewer (URL printed)."""
    if args.save:
        rr.save(args.save, recording=rec)
        return
    if args.spawn:
        rr.spawn(recording=rec)
        return
    grpc_port = args.grpc_port or _free_port()
    web_port = args.web_port or _free_port()
    url = rr.serve_grpc(grpc_port=grpc_port, recording=rec)
    rr.serve_web_viewer(web_port=web_port, open_browser=False, connect_to=url)
    print(f"hri rerun: http://127.0.0.1:{web_port}/?url={url}  (data at {url}; Ctrl-C to stop)", flush=True)


def cmd_rerun(args: argparse.Namespace) -> int:
    rr = _rr()
    from hri.recording import RecordingError, _stop_on_signals
    from hri.viewers.feed import replay_recording

    rec = rr.RecordingStream("hri-fusion")
    _open_output(args, rr, rec)
    sink = RerunSink(rec)
    stop = threading.Event()
    _stop_on_signals(stop)
    if args.recording:
        try:
            n = replay_recording(args.recording, sink)
        except RecordingError as exc:
            print(f"hri rerun: {exc}", file=sys.stderr)
            return 2
        print(f"hri rerun: {n} samples of {args.recording} logged", file=sys.stderr, flush=True)
        if not args.save and not args.spawn:
            stop.wait()  # keep serving the viewer
    else:
        _run_live(args, sink, stop)
    rec.flush()
    rr.disconnect(recording=rec)
    return 0


def _run_live(args: argparse.Namespace, sink: RerunSink, stop: threading.Event) -> None:
    from common.runner import setup_logging
    from common.transport import open_session, resolve
    from hri.viewers.feed import LiveFeed

    resolve(args)
    keys = Keys(args.prefix)
    log = setup_logging("hri.rerun", args.log_level)
    session = open_session(args, log, stop)
    if session is None:
        return
    feed = LiveFeed(session, keys, sink, log, skip=(keys.audio("*"),))
    print(f"hri rerun: logging the live stack ({keys.prefix}/**)", flush=True)  # subscribed: nothing is missed now
    stop.wait(args.duration)
    feed.close()
    session.close()
    c = feed.counts
    print(
        f"hri rerun: {c.shown} samples logged, {sum(c.invalid.values())} invalid; viewer behind: {c.skipped} "
        f"stream samples skipped, {c.dropped} events dropped",
        file=sys.stderr,
    )
