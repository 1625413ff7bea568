"""Process shell of the gesture service: Frame -> Hands and Bodies (every frame) and GestureEvents."""

from __future__ import annotations

import argparse
import time

import numpy as np

from common.image import frame_handler
from common.runner import App, Delivery, Service, StartupError, serve, service_parser
from common.schema import DepthFrame, Frame, Ray3D, SpeechDecoding
from common.settings import add_option, add_settings, from_args
from common.speech_first import SpeechFirst
from common.stack import node
from services.gesture.core import CameraGraphs, GestureCore, GestureSettings, build_graphs, event_sample
from services.gesture.faces import FaceConfig
from services.gesture.landmarks import LandmarkError
from services.gesture.people_stage import PeopleOfFrame
from services.gesture.pose_rotation import MAX_POSES
from services.gesture.space import FrameRays
from services.gesture.temporal import Event
from services.gesture.warm import GraphSupply

EPILOG = """\
examples:
  hri-gesture                          # lite hand model, every camera, robot (non-mirrored) camera
  hri-gesture --model full --max-hands 1
  hri-gesture --mirrored               # selfie-style camera image: `hand` stays the person's own hand
  hri-gesture --no-body                # hands only (saves the body stage's cost; no pointing at room distance)
"""


# depth frames kept per camera to find the one of a colour frame: the depth input's queue (common/stack.py)
DEPTH_KEPT = node("gesture").input("depth").maxlen


def build_parser() -> argparse.ArgumentParser:
    parser = service_parser(
        "gesture",
        "Find hands and the body (MediaPipe), classify gestures over time, "
        "publish Hands and Bodies for every frame and GestureEvents (start/hold/end) with a "
        "pointing ray from the finger or the arm.",
        EPILOG,
    )
    add_option(parser, "--model", "lite", "the hand landmark model", choices=("lite", "full"))
    add_option(parser, "--max-hands", 2, "hands to track per camera", at_least=1, metavar="N")
    add_option(
        parser, "--mirrored", False, "the camera image is mirrored (a selfie view, unlike a robot's normal camera)"
    )
    add_option(parser, "--start-frames", 3, "frames a gesture must hold to start", at_least=1, metavar="N")
    add_option(
        parser,
        "--start-ms",
        0.0,
        "or: milliseconds it must hold to start, whichever comes first",
        at_least=0,
        metavar="MS",
        default_text="0: frames only",
    )
    add_option(parser, "--end-frames", 3, "frames it must be absent to end", at_least=1, metavar="N")
    add_option(
        parser,
        "--idle-end",
        1.0,
        "seconds without frames from a camera after which its gestures end",
        above=0,
        metavar="S",
    )
    add_option(
        parser,
        "--body",
        True,
        "run the body stage (MediaPipe Pose): arm pointing at room distance, raised vs resting palms; "
        "publishes Bodies (--no-body for hands only)",
    )
    add_option(
        parser,
        "--pose-max-rate",
        10.0,
        "run full-body pose at most this many times per second of source time (on a 30 fps camera 10 = every 3rd "
        "frame, 15 = every 2nd); between its runs the last skeleton is carried, its hands' ends moved with the "
        "tracked hands (Body.pose_age_ms says how old it is); 0 = every frame",
        at_least=0,
        metavar="HZ",
    )
    add_option(
        parser,
        "--ray",
        "eyes",
        "body ray: eyes -> fingertip (forearm when the eyes are out of view) or forearm (elbow -> fingertip)",
        choices=("eyes", "forearm"),
    )
    add_option(
        parser,
        "--persons-every",
        2,
        "run the person stage (faces, a body per person, stable person ids: Persons) on every Nth frame; 0 = off",
        at_least=0,
        metavar="N",
    )
    add_option(
        parser,
        "--persons-max-poses",
        MAX_POSES,
        "the person stage poses at most N persons' regions per run, in turn (the longest unposed first, a new "
        "face first of all); the others keep their last skeleton (Body.pose_age_ms says how old); 0 = no cap",
        at_least=0,
        metavar="N",
    )
    add_option(
        parser,
        "--hands-idle-every",
        2,
        "while no hand is in view, look for hands on every Nth frame only (a hand coming into view is found at "
        "most N-1 frames late; a hand in view is tracked on every frame); 1 = every frame",
        at_least=1,
        metavar="N",
    )
    add_option(
        parser,
        "--stagger",
        True,
        "spread the paced stages over frames: the face stage, the idle hand search and the person stage, when due on "
        "a frame full pose runs on, move to the next frame (each keeps its rate; --no-stagger: each runs when due)",
    )
    add_option(
        parser,
        "--speech-first",
        True,
        "while speech decodes an utterance (its SpeechDecoding samples), skip full pose and the person stage "
        "(hands, stop palms and the face stage keep running: whoever speaks next is read from the mouths), so that "
        "the decode gets the cores (issue #42)",
    )
    add_option(parser, "--cams", "*", "comma-separated camera ids to process (* for all)", metavar="IDS")
    add_option(
        parser,
        "--spare-graphs",
        0,
        "sets of MediaPipe graphs kept built ahead for cameras not seen yet (~300 MB each): a new camera is served "
        "from its first frame. The cameras --cams names (or, with a wildcard, the first camera) get theirs at start; "
        "with 0 a later new camera's are built in the background while its frames are skipped",
        at_least=0,
        metavar="N",
    )
    add_option(
        parser,
        "--faces",
        True,
        "run the face stage (MediaPipe Face Mesh): publishes Faces, mouths and head orientation for who is "
        "speaking (--no-faces saves its cost)",
    )
    add_settings(parser.add_argument_group("face stage (docs/people.md)"), FaceConfig)
    return parser


def settings_of(args: argparse.Namespace) -> GestureSettings:
    return GestureSettings(
        model=args.model,
        max_hands=args.max_hands,
        mirrored=args.mirrored,
        start_frames=args.start_frames,
        end_frames=args.end_frames,
        start_s=args.start_ms / 1000.0,
        ray_from=args.ray,
        body=args.body,
        pose_max_rate=args.pose_max_rate,
        persons_every=args.persons_every,
        persons_max_poses=args.persons_max_poses,
        hands_idle_every=args.hands_idle_every,
        faces=args.faces,
        face=from_args(FaceConfig, args),
        stagger=args.stagger,
    )


class GestureApp(App):
    """Frame (+ the DepthFrame of the same capture) -> GestureCore -> Persons, Faces, Hands, Bodies and
    GestureEvents."""

    node = "gesture"
    tick_interval = 0.1

    def __init__(self, args: argparse.Namespace) -> None:
        self.args = args
        self.settings = settings_of(args)
        self.last_frame: dict[str, tuple[float, Frame]] = {}  # cam -> (monotonic time it was done, latest frame)
        self.speech_first = SpeechFirst()

    def open(self, service: Service) -> None:
        """The graphs of the cameras --cams names (with a wildcard: of the first camera, and --spare-graphs more) are
        built and warmed here, before the service declares itself live: their first frames are served at once."""
        s, self.service = self.settings, service
        self.supply: GraphSupply[CameraGraphs] = GraphSupply(
            lambda: build_graphs(s),
            self.args.spare_graphs,
            lambda exc: service.log.error("could not build a camera's graphs: %s", exc),
            lambda seconds: service.log.info("graphs for a new camera built and warmed in %.1f s", seconds),
            self.count_graph_sets,
        )
        cams = [c.strip() for c in self.args.cams.split(",")]
        named = [c for c in cams if "*" not in c]
        try:
            self.supply.prepare(named, max(1, self.args.spare_graphs) if len(named) < len(cams) else 0)
        except LandmarkError as exc:  # fail now, with the reason
            raise StartupError(str(exc)) from None
        service.log.info("graphs of %d camera(s) built and warmed", self.supply.built)
        # the rates its paced stages run at (`hri up` sets them from the machine's cores: common/budget.py)
        service.counters.set("pose_max_rate_mhz", round(1000 * s.pose_max_rate))
        service.counters.set("faces_max_rate_mhz", round(1000 * s.face.faces_max_rate))
        service.counters.set("persons_every", s.persons_every)
        self.core = GestureCore(s, service.source, DEPTH_KEPT)
        service.on_close(self.core.close)
        service.on_close(self.supply.close)
        self.tick = self.end_idle_streams

    def wire(self, service: Service) -> None:
        if self.args.speech_first:
            service.subscribe_input("decoding", self.on_decoding)
        for cam in self.args.cams.split(","):
            service.subscribe_input("frame", frame_handler(service, self.on_image), cam=cam.strip())
            # a camera without depth sends none: nothing changes (2-D rays only)
            service.subscribe_input("depth", self.on_depth, cam=cam.strip())

    def on_depth(self, delivery: Delivery) -> None:
        assert isinstance(delivery.sample, DepthFrame)  # the runner validated it as the topic's schema
        self.core.add_depth(delivery.sample)

    def has_graphs(self, cam: str) -> bool:
        """Whether `cam`'s graphs exist; a new camera takes a built set, else one is built off the frame path."""
        if cam in self.core.cameras:
            return True
        graphs = self.supply.take(cam)
        if graphs is None:
            return False
        self.core.adopt(cam, graphs)
        self.service.log.info("new camera %s: its graphs are ready", cam)
        return True

    def count_graph_sets(self, built: int, ready: int) -> None:
        """The stats gauges of the graph sets: built so far, and ready for a camera not seen yet."""
        self.service.counters.set("graph_sets_built", built)
        self.service.counters.set("graph_sets_ready", ready)

    def on_decoding(self, delivery: Delivery) -> None:
        notice = delivery.sample
        assert isinstance(notice, SpeechDecoding)  # the runner validated it as the topic's schema
        self.speech_first.heard(notice.mic, notice.decoding, time.monotonic())

    def on_image(self, frame: Frame, img: np.ndarray) -> None:
        if not self.has_graphs(frame.cam):  # a new camera whose graphs are being built: no frame waits for them
            self.service.counters.add("skipped_building_graphs")
            return
        service, unmatched = self.service, self.core.depth_unmatched
        ease = self.speech_first.easing(time.monotonic())
        result = self.core.process(frame, img, fresh=frame.cam not in self.last_frame, ease=ease)
        if ease:
            self.speech_first.eased += 1
            service.counters.set("eased_for_speech", self.speech_first.eased)
        if self.core.depth_unmatched > unmatched:
            service.counters.add("depth_unmatched")
        if result.persons is not None:  # the person stage ran on this frame: its Persons
            service.publish_output("persons", result.persons, cam=frame.cam)
        if result.faces is not None:  # the face stage's sample (tied to the persons: GestureCore.link)
            service.publish_output("faces", result.faces, cam=frame.cam)
        service.publish_output("hands", result.hands, cam=frame.cam)
        if result.bodies is not None:
            service.publish_output("bodies", result.bodies, cam=frame.cam)
        self.publish_events(frame, result.events, result.rays3d, result.hand_rays3d, result.seen)
        if result.rays3d is not None and result.rays3d.error:
            service.counters.reject("bad_value", f"depth of {frame.cam} seq {frame.seq}: {result.rays3d.error}")
        # stamped after the work: a slow frame on a busy machine must not look like a camera gone quiet
        self.last_frame[frame.cam] = (time.monotonic(), frame)

    def publish_events(
        self,
        frame: Frame,
        events: list[Event],
        rays3d: FrameRays | None = None,
        hand_rays3d: dict[str, Ray3D | None] | None = None,
        seen: PeopleOfFrame | None = None,
    ) -> None:
        service = self.service
        for ev in events:
            event = event_sample(frame, ev, service.source, rays3d, hand_rays3d, seen)
            service.publish_output("event", event, lossless=True, realtime=ev.gesture == "open_palm", cam=frame.cam)
            if ev.phase != "hold":
                service.log.info("%s %s (%s hand) on %s", ev.gesture, ev.phase, ev.hand, frame.cam)

    def end_idle_streams(self) -> None:
        """A camera that stopped sends no frame to show the hand is gone: end its gestures after --idle-end s."""
        now, idle_end = time.monotonic(), self.args.idle_end
        for cam, (done, frame) in list(self.last_frame.items()):
            if now - done >= idle_end:
                del self.last_frame[cam]
                ended = self.core.cameras[cam].tracker.flush()
                if ended:
                    self.service.counters.add("ended_idle_stream", len(ended))
                    self.service.log.info("no frame from %s for %.1f s: its gestures end", cam, idle_end)
                    self.publish_events(frame, ended)


def main(argv: list[str] | None = None) -> None:
    args = build_parser().parse_args(argv)
    serve(GestureApp(args), args)


if __name__ == "__main__":
    main()
