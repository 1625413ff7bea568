"""Process shell of the gesture service: Frame -> Hands and Bodies (every frame) and GestureEvents."""

from __future__ import annotations

import argparse
import collections
import time
from typing import cast

import numpy as np

from common.image import frame_handler
from common.runner import Service, main_exit, service_parser
from common.schema import Bodies, Body, Frame, GestureEvent, GestureName, Hand, Handedness, Hands, Ray
from common.settings import add_option
from common.stack import node
from services.gesture.landmarks import HandLandmarker, LandmarkError, PoseLandmarker
from services.gesture.people_stage import CameraPeople, PeopleOfFrame, event_person, hand_person, other_arms
from services.gesture.space import FrameRays
from services.gesture.temporal import GestureTracker

EPILOG = """\
examples:
  hri-gesture                          # lite hand model, every camera, robot (non-mirrored) camera
  hri-gesture --model full --max-hands 1
  hri-gesture --mirrored               # selfie-style camera image: `hand` stays the person's own hand
  hri-gesture --no-body                # hands only (saves the body stage's cost; no pointing at room distance)
"""


# depth frames kept per camera to find the one of a colour frame: the depth input's queue (common/stack.py)
DEPTH_KEPT = node("gesture").input("depth").maxlen


def to_ray(ray, ray3d=None) -> Ray | None:
    if ray is None:
        return None
    return Ray(
        origin=[round(v, 2) for v in ray.origin],
        direction=list(ray.direction),
        confidence=ray.confidence,
        source=ray.source,
        ray3d=ray3d,
    )


def to_body(landmarks, arms, rays3d: FrameRays | None = None) -> Body:
    """A pose skeleton (33x3) and the last frame's judged arms -> the wire `Body` (3-D rays when depth is known)."""
    rays = {arm.side: to_ray(ray, rays3d.arm(arm.side) if rays3d and ray else None) for arm, ray in arms}
    return Body(
        landmarks=[[round(x, 1), round(y, 1)] for x, y in landmarks[:, :2].tolist()],
        visibility=[round(min(1.0, max(0.0, v)), 3) for v in landmarks[:, 2].tolist()],
        left_ray=rays.get("left"),
        right_ray=rays.get("right"),
    )


def people_bodies(
    frame: Frame, skeleton: np.ndarray | None, arms: list, rays3d: FrameRays | None, seen: PeopleOfFrame | None
) -> list[Body]:
    """The full-frame skeleton with the tracker's arms, plus (on the person stage's frames) every other person's."""
    main = [] if skeleton is None else [to_body(skeleton, arms, rays3d)]
    if seen is None:
        return main
    for body in main:
        body.person = seen.main_person
    others = (
        [(p.id, p.body) for p in seen.persons if p.id != seen.main_person and p.body is not None] if seen.ran else []
    )
    for pid, b in others:  # their own arms, this frame's; no 3-D rays (FrameRays lifts the full-frame skeleton)
        main.append(to_body(b, other_arms(b, frame.width, frame.height)))
        main[-1].person = pid
    return main


def close_all(graphs: list[HandLandmarker | PoseLandmarker], people: CameraPeople) -> None:
    for graph in graphs:
        graph.close()
    people.close()


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
    add_option(parser, "--cams", "*", "comma-separated camera ids to process (* for all)", metavar="IDS")
    return parser


def main(argv: list[str] | None = None) -> None:
    args = build_parser().parse_args(argv)

    service = Service("gesture", args)
    try:
        HandLandmarker(args.model, args.max_hands, args.mirrored).close()  # fail now, with the reason
        if args.body:
            PoseLandmarker().close()
    except LandmarkError as exc:
        service.log.error("%s", exc)
        main_exit(2)
    landmarkers: dict[str, HandLandmarker] = {}
    posers: dict[str, PoseLandmarker] = {}
    trackers: dict[str, GestureTracker] = {}
    last_frame: dict[str, tuple[float, Frame]] = {}  # cam -> (monotonic time it was done, latest frame)
    depths: dict[str, collections.deque] = {}  # cam -> the last DEPTH_KEPT DepthFrames
    people = CameraPeople(args.persons_every)  # issue #33: Persons, a body per person, whose hand is whose
    service.on_close(lambda: close_all([*landmarkers.values(), *posers.values()], people))
    if not service.connect():
        main_exit(0)

    def on_image(frame: Frame, img) -> None:
        if frame.cam not in landmarkers:  # one graph per stream: MediaPipe tracks between frames
            landmarkers[frame.cam] = HandLandmarker(args.model, args.max_hands, args.mirrored)
        went_back = frame.cam in last_frame and frame.stamp < last_frame[frame.cam][1].stamp
        if frame.cam not in trackers or went_back:
            # new stream, or the runner accepted a new timeline (common/stamps.py): gestures start afresh
            trackers[frame.cam] = GestureTracker(
                start_frames=args.start_frames,
                end_frames=args.end_frames,
                start_time=args.start_ms / 1000.0,
                ray_from=args.ray,
            )
            if args.body:
                posers[frame.cam] = PoseLandmarker()
        observations = landmarkers[frame.cam].detect(img)
        skeleton = posers[frame.cam].detect(img) if args.body else None
        tracker = trackers[frame.cam]
        rays3d = frame_rays(frame, skeleton, posers[frame.cam].world if args.body and skeleton is not None else None)
        joints3d = rays3d.joints() if rays3d is not None else None  # with depth, arms are judged in 3-D
        tracked, events = tracker.update(frame.stamp, observations, skeleton, (frame.width, frame.height), joints3d)
        hand_rays3d = {
            o.hand: rays3d.hand(o.landmarks, tip=t.ray.source == "hand")
            for o, t in zip(observations, tracked)
            if rays3d is not None and t.ray is not None
        }
        seen = people.update(frame, img, skeleton, observations, rays3d, fresh=frame.cam not in last_frame)
        if seen is not None and seen.ran:  # the stage ran on this frame: its Persons
            service.publish_output("persons", people.sample(frame, seen, service.source), cam=frame.cam)
        hands = [
            Hand(
                hand=cast(Handedness, o.hand),
                score=round(o.score, 4),
                landmarks=[[round(x, 2), round(y, 2)] for x, y in o.landmarks.tolist()],
                gesture=cast(GestureName | None, t.gesture),
                ray=to_ray(t.ray, hand_rays3d.get(o.hand)),
                person=hand_person(seen, k),
            )
            for k, (o, t) in enumerate(zip(observations, tracked))
        ]
        service.publish_output(
            "hands",
            Hands(
                stamp=frame.stamp,
                source=service.source,
                seq=frame.seq,
                cam=frame.cam,
                width=frame.width,
                height=frame.height,
                hands=hands,
            ),
            cam=frame.cam,
        )
        if args.body:
            service.publish_output(
                "bodies",
                Bodies(
                    stamp=frame.stamp,
                    source=service.source,
                    seq=frame.seq,
                    cam=frame.cam,
                    width=frame.width,
                    height=frame.height,
                    bodies=people_bodies(frame, skeleton, tracker.last_arms, rays3d, seen),
                ),
                cam=frame.cam,
            )
        publish_events(frame, events, rays3d, hand_rays3d, seen)
        if rays3d is not None and rays3d.error:
            service.counters.reject("bad_value", f"depth of {frame.cam} seq {frame.seq}: {rays3d.error}")
        # stamped after the work: a slow frame on a busy machine must not look like a camera gone quiet
        last_frame[frame.cam] = (time.monotonic(), frame)

    def frame_rays(frame: Frame, skeleton, world) -> FrameRays | None:
        """The 3-D rays of this frame, when the depth of the same capture (same seq and stamp) has come."""
        depth = next(
            (d for d in reversed(depths.get(frame.cam, ())) if d.seq == frame.seq and d.stamp == frame.stamp), None
        )
        if depth is None:
            if frame.cam in depths:
                service.counters.add("depth_unmatched")  # a camera with depth, but not of this capture (yet)
            return None
        return FrameRays(depth, skeleton, world)  # decoded only when a body is seen

    def on_depth(d) -> None:
        depths.setdefault(d.sample.cam, collections.deque(maxlen=DEPTH_KEPT)).append(d.sample)

    def publish_events(
        frame: Frame,
        events: list,
        rays3d: FrameRays | None = None,
        hand_rays3d: dict | None = None,
        seen: PeopleOfFrame | None = None,
    ) -> None:
        for ev in events:
            ray3d = None
            if ev.ray is not None and rays3d is not None:
                ray3d = rays3d.arm(ev.hand) if ev.ray.source == "body" else (hand_rays3d or {}).get(ev.hand)
            service.publish_output(
                "event",
                GestureEvent(
                    stamp=frame.stamp,
                    source=service.source,
                    cam=frame.cam,
                    width=frame.width,
                    height=frame.height,
                    gesture=ev.gesture,
                    phase=ev.phase,
                    start=ev.start,
                    end=ev.end,
                    score=ev.score,
                    hand=ev.hand,
                    ray=to_ray(ev.ray, ray3d),
                    person=event_person(seen, ev.hand, ev.ray),
                ),
                lossless=True,
                realtime=ev.gesture == "open_palm",
                cam=frame.cam,
            )
            if ev.phase != "hold":
                service.log.info("%s %s (%s hand) on %s", ev.gesture, ev.phase, ev.hand, frame.cam)

    def end_idle_streams() -> None:
        """A camera that stopped sends no frame to show the hand is gone: end its gestures after --idle-end s."""
        now = time.monotonic()
        for cam, (done, frame) in list(last_frame.items()):
            if now - done >= args.idle_end:
                del last_frame[cam]
                ended = trackers[cam].flush()
                if ended:
                    service.counters.add("ended_idle_stream", len(ended))
                    service.log.info("no frame from %s for %.1f s: its gestures end", cam, args.idle_end)
                    publish_events(frame, ended)

    for cam in args.cams.split(","):
        service.subscribe_input("frame", frame_handler(service, on_image), cam=cam.strip())
        # a camera without depth sends none: nothing changes (2-D rays only)
        service.subscribe_input("depth", on_depth, cam=cam.strip())
    main_exit(service.run(tick=end_idle_streams, tick_interval=0.1))


if __name__ == "__main__":
    main()
