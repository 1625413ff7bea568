"""Real photos of people pointing, through the real stages in process (issue #31): the gesture service's own
per-frame path (MediaPipe hands + pose, the tracker, `to_ray`) gives the Hands, vision's own pipeline with the real
YOLOX-Nano gives the Detections, and the fusion core decides "pick up that one" said while the photo is shown.

Judged per photo: `safe` — no command or question proposes a person or something "pick up" cannot apply to
(common/language.py affordances); `right` — the command acts on the object pointed at, or it is an honest question
(it asks, and the object pointed at is among its candidates, or it was not detected at all, or the target is out of
the image). Shared by tests/test_fusion_pointing_real.py and benchmarks/pointing_people.py."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, cast

import cv2

from common.language import GRASP_MAX_EXTENT_M, graspable_class
from common.schema import Clarification, FusedCommand, GestureName, Hand, Handedness, Hands, Sample, Target
from testkit.scenarios import KEYS, Scenario, Step, detections_at, run_in_process, say
from testkit.scenarios.indoor import Seen, vision_pipeline

FRAMES = 8  # the photo shown like a camera holding still, 10 frames a second
COMMAND = "pick up that one"


@dataclass(frozen=True)
class Photo:
    folder: str  # under shared/data
    name: str
    targets: tuple[tuple[float, float], ...]  # pixels of the object(s) pointed at; () = out of the image


# Targets from the folders' READMEs (pointing/README.md, people_multi/people_multi.json), checked by eye there.
PHOTOS = (
    Photo("pointing", "room_woman_0126_t2_right_arm_to_image_right.png", ((761, 478), (933, 518))),
    Photo("pointing", "room_woman_0126_t3_right_arm_to_image_left.png", ((592, 485), (424, 521))),
    Photo("pointing", "room_woman_0219_t6_left_arm_to_image_right.png", ((853, 474),)),
    Photo("people_multi", "room_pointer_bystander_0219_t21.png", ((852, 494), (867, 551))),
    Photo("people_multi", "room_pointer_bystander_0219_t1.png", ((509, 485), (541, 503))),
    Photo("pointing", "nico_table_f01_red_cube.jpg", ((195, 535),)),
    Photo("pointing", "nico_table_f05_yellow_cube.jpg", ((345, 523),)),
    Photo("pointing", "nico_table_f06_row_middle_yellow.jpg", ((426, 539),)),
    Photo("pointing", "nico_table_f07_green_cube.jpg", ((470, 528),)),
    Photo("pointing", "nico_table_f10_row_right_green.jpg", ((505, 538),)),
    Photo("pointing", "lowcam_man_image3_left_arm_to_image_left.jpeg", ()),
    Photo("pointing", "lowcam_man_image4_left_arm_to_image_right.jpeg", ()),
    Photo("pointing", "lowcam_man_image5_left_arm_raised_forward.jpeg", ()),
    Photo("pointing", "lowcam_man_image7_right_arm_to_floor.jpeg", ()),
    Photo("pointing", "lowcam_man_image8_right_arm_at_camera.jpeg", ()),
)


def hands_on_photo(img: Any, frames: int = FRAMES) -> list[Hands]:
    """The Hands the gesture service publishes while the photo is shown `frames` times (stamps 0, 0.1, …)."""
    from services.gesture.core import to_ray
    from services.gesture.landmarks import HandLandmarker, PoseLandmarker
    from services.gesture.temporal import GestureTracker

    hands, pose, tracker = HandLandmarker("lite", video=True), PoseLandmarker(video=True), GestureTracker()
    h, w = img.shape[:2]
    out = []
    try:
        for i in range(frames):
            observations = hands.detect(img)
            tracked, _ = tracker.update(i / 10, observations, pose.detect(img), (w, h))
            out.append(
                Hands(
                    stamp=i / 10,
                    source="gesture/cam0",
                    seq=i,
                    cam="cam0",
                    width=w,
                    height=h,
                    hands=[
                        Hand(
                            hand=cast(Handedness, o.hand),
                            score=round(o.score, 4),
                            landmarks=[[round(x, 2), round(y, 2)] for x, y in o.landmarks.tolist()],
                            gesture=cast(GestureName | None, t.gesture),
                            ray=to_ray(t.ray),
                        )
                        for o, t in zip(observations, tracked)
                    ],
                )
            )
    finally:
        hands.close()
        pose.close()
    return out


def _hands_step(sample: Hands) -> Step:
    def build(base: float) -> tuple[str, Sample]:
        moved = Hands(
            stamp=base + sample.stamp,
            source=sample.source,
            seq=sample.seq,
            cam=sample.cam,
            width=sample.width,
            height=sample.height,
            hands=sample.hands,
        )
        return KEYS.hands("cam0"), moved

    return Step(sample.stamp, build)


def scenario(seen: Seen, hands: list[Hands], text: str = COMMAND) -> Scenario:
    """Detections and Hands of the photo for FRAMES / 10 s; the words said over the last 0.6 s of it."""
    end = (len(hands) - 1) / 10
    steps = [detections_at(i / 10, seen.objects, seen.quality, seen.width, seen.height) for i in range(len(hands))]
    steps += [_hands_step(h) for h in hands]
    steps.append(say(end - 0.6, end, text))
    return Scenario(text, sorted(steps, key=lambda s: s.t), [])


def _holds(target: Target, pixel: tuple[float, float]) -> bool:
    x, y, w, h = target.bbox
    return x <= pixel[0] <= x + w and y <= pixel[1] <= y + h


def unsafe(targets: list[Target]) -> list[str]:
    """What "pick up" must never be offered: people, classes no arm lifts, objects measured too big."""
    bad = []
    for t in targets:
        size = max(t.extent[0], t.extent[1]) if t.extent else 0.0
        if t.label == "person" or not graspable_class(t.label) or size > GRASP_MAX_EXTENT_M:
            bad.append(f"{t.id} ({t.label})")
    return bad


@dataclass(frozen=True)
class Verdict:
    photo: Photo
    pointed: bool  # a pointing ray reached fusion
    detected_target: bool  # vision boxed the object pointed at
    outcome: str  # "command <id> (<label>)" / "<reason> question: …"
    seen: str  # what vision reported: "person, bottle, dining table"
    safe: bool
    right: bool


def judge(photo: Photo, seen: Seen, hands: list[Hands], outputs: list[Sample]) -> Verdict:
    proposed: list[Target] = []
    outcome = "nothing"
    commanded: Target | None = None
    for o in outputs:
        if isinstance(o, FusedCommand):
            commanded = o.target
            proposed += [o.target] if o.target else []
            outcome = f"command {o.intent} " + (f"{o.target.id} ({o.target.label})" if o.target else "(no target)")
        elif isinstance(o, Clarification):
            proposed += o.candidates
            outcome = f"{o.reason} question: {o.question}"
    # the object pointed at is "detected" when a box of something graspable holds its pixel (a table's box holding
    # a cube on it is not the cube)
    detected = [
        o for o in seen.objects if graspable_class(o.label) and any(_holds_box(o.bbox, p) for p in photo.targets)
    ]
    if commanded is not None:
        right = any(_holds(commanded, p) for p in photo.targets) and not unsafe([commanded])
    else:  # a question: honest when the object pointed at is offered, or was never seen, or is out of the image
        offered = any(any(_holds(c, p) for p in photo.targets) for c in proposed)
        right = outcome != "nothing" and (offered or not detected)
    pointed = any(h.ray is not None for frame in hands for h in frame.hands)
    labels = ", ".join(sorted(o.label for o in seen.objects)) or "nothing"
    return Verdict(photo, pointed, bool(detected), outcome, labels, not unsafe(proposed), right)


def _holds_box(bbox: list[float], pixel: tuple[float, float]) -> bool:
    x, y, w, h = bbox
    return x <= pixel[0] <= x + w and y <= pixel[1] <= y + h


def evaluate(shared: Path, model: Path, photos: tuple[Photo, ...] = PHOTOS) -> list[Verdict]:
    see: Callable[[Path], Seen] = vision_pipeline(model)
    out = []
    for photo in photos:
        path = shared / "data" / photo.folder / photo.name
        if not path.exists():
            continue
        seen = see(path)
        img = cv2.imread(str(path))
        if img is None:
            raise FileNotFoundError(f"cannot read {path}")
        scale = seen.width / img.shape[1]
        if scale != 1.0:  # vision saw it resized (longest side <= 960): the same size for gesture
            img = cv2.resize(img, (seen.width, seen.height))
        scaled = Photo(photo.folder, photo.name, tuple((x * scale, y * scale) for x, y in photo.targets))
        hands = hands_on_photo(img)
        out.append(judge(scaled, seen, hands, run_in_process(scenario(seen, hands))))
    return out


def report(verdicts: list[Verdict]) -> str:
    lines = [
        "| photo | vision saw | pointing seen | target detected | outcome | safe | right or honest |",
        "|---|---|---|---|---|---|---|",
    ]
    for v in verdicts:
        lines.append(
            f"| {v.photo.name} | {v.seen} | {'yes' if v.pointed else 'no'} | "
            f"{'yes' if v.detected_target else ('out of view' if not v.photo.targets else 'no')} | {v.outcome} | "
            f"{'yes' if v.safe else 'NO'} | {'yes' if v.right else 'no'} |"
        )
    n = len(verdicts)
    lines.append(
        f"\nsafe {sum(v.safe for v in verdicts)}/{n}, right or honest {sum(v.right for v in verdicts)}/{n}, "
        f"pointing seen {sum(v.pointed for v in verdicts)}/{n}"
    )
    return "\n".join(lines)
