"""Scenes made from the real YOLOX-Nano detector's output on real photos (../shared/models/yolox_nano.onnx).

The detections are computed by the vision service's own ONNX backend (services/vision/yolo.py, the YOLOX family
as shared/models/MODEL.md describes it). `real_scenarios()` turns them into
scenarios of the suite: the tests run them in process and over Zenoh, benchmarks/fusion_eval.py scores them.
Nothing of shared/ is copied: photos are read where they are.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Callable

from common.schema import DetectedObject, ImageQuality
from testkit.scenarios import Expect, Scenario, Step, by_time, detections_at, pointing, say

if TYPE_CHECKING:
    from services.vision.yolo import YoloDetector

# The nano model's scores are moderate (a real cup at 0.30-0.32 in these photos); 0.25 keeps them with margin.
MIN_SCORE = 0.25
NMS_IOU = 0.45
Found = list[tuple[str, float, list[float]]]  # (COCO label, score, [x, y, w, h] px)


def yolox_detector(model: Path, detector: YoloDetector | None = None) -> Callable[[Path], tuple[Found, int, int]]:
    """A function photo -> (detections, width, height): the vision service's own ONNX backend
    (services/vision/yolo.py, which reads the YOLOX family from the model's output) on the CPU, at MIN_SCORE and
    NMS_IOU; or `detector` (testkit/golden.py's, which rounds what it finds)."""
    import cv2

    from services.vision.yolo import YoloDetector

    detector = detector or YoloDetector(str(model), conf_threshold=MIN_SCORE, iou_threshold=NMS_IOU)
    assert detector.family == "yolox", detector.describe()

    def detect(path: Path) -> tuple[Found, int, int]:
        img = cv2.imread(str(path))
        if img is None:
            raise FileNotFoundError(f"cannot read the photo {path}")
        h, w = img.shape[:2]
        # the service clips boxes to [0, w] × [0, h]; the scenes keep them inside the last pixel as before
        found = [
            (
                label,
                score,
                [min(x, w - 1), min(y, h - 1), min(bw, w - 1 - min(x, w - 1)), min(bh, h - 1 - min(y, h - 1))],
            )
            for label, score, (x, y, bw, bh) in detector.detect(img)
        ]
        return found, w, h

    return detect


def object_id(found: Found, i: int) -> str:
    return f"{found[i][0].replace(' ', '_')}_{i}"


def scene_steps(found: Found, w: int, h: int, t0: float = -1.5, t1: float = 2.5, every: float = 0.2) -> list[Step]:
    """Detections samples of one real frame (the scene does not change) every `every` s over [t0, t1]."""
    objects = [
        DetectedObject(
            id=object_id(found, i),
            label=label,
            color=None,
            score=round(score, 3),
            bbox=box,
            center=[box[0] + box[2] / 2, box[1] + box[3] / 2],
        )
        for i, (label, score, box) in enumerate(found)
    ]

    quality = ImageQuality(brightness=0.5, contrast=0.5, sharpness=0.5)
    n = int(round((t1 - t0) / every))
    return [
        detections_at(round(t0 + i * every, 6), objects, quality, w, h, what="real detections") for i in range(n + 1)
    ]


def real_scene(found: Found, w: int, h: int, text: str) -> list[Step]:
    return by_time(scene_steps(found, w, h) + pointing(None) + [say(0.0, 1.5, text)])


# (photo under shared/ or "repo:" + a path in the repository, what is said, expected outcome):
# ("command", label, intent) acts on the one detection with that label; ("ambiguous", labels) asks among the detections
# with those labels; ("not_found", question start) asks, saying what it cannot see or does not know.
CUP_PHOTO = "data/people/none_0a272153-56c7-42d5-a17d-cd307a1cd6d4.jpg"  # a person, a clock, a bottle, a cup
CUP_PHOTO_2 = "data/people/call_17b3aa02-dc4d-448d-8601-e2b67193d436.jpg"  # a person holding a cup
FRUIT_PHOTO = "repo:data/images/tabletop/smarties.png"  # candies the model takes for oranges, apples, frisbees
PERSON_PHOTO = "data/pointing/lowcam_man_image3_left_arm_to_image_left.jpeg"
CASES: list[tuple[str, str, tuple]] = [
    (CUP_PHOTO, "Pick up the cup.", ("command", "cup", "pick_up")),
    (CUP_PHOTO, "Bring me the mug, please.", ("command", "cup", "bring")),
    (CUP_PHOTO, "Look at the person.", ("command", "person", "look_at")),
    (CUP_PHOTO, "Could you, uh, fetch the bottle?", ("command", "bottle", "bring")),
    (CUP_PHOTO, "Give me a drink.", ("ambiguous", ("bottle", "cup"))),
    (CUP_PHOTO, "Hand me the pitcher, please.", ("not_found", "I don't know what a pitcher is. I can see ")),
    (CUP_PHOTO_2, "Hand me the cup.", ("command", "cup", "bring")),
    (PERSON_PHOTO, "Follow the person.", ("command", "person", "follow")),
    (FRUIT_PHOTO, "Bring me the fruit.", ("ambiguous", ("apple", "orange", "banana"))),
    (FRUIT_PHOTO, "Bring me the banana.", ("not_found", "I can't see the banana. I can see an ")),
]


def real_scenarios(detect: Callable[[Path], tuple[Found, int, int]], photo: Callable[[str], Path]) -> list[Scenario]:
    """The CASES as scenarios, with expectations in the detections' ids."""
    cache: dict[str, tuple[Found, int, int]] = {}
    out = []
    for image, text, (kind, what, *intent) in CASES:
        if image not in cache:
            cache[image] = detect(photo(image))
        found, w, h = cache[image]
        if kind == "command":
            ids = [object_id(found, i) for i, f in enumerate(found) if f[0] == what]
            expect = Expect(
                "command",
                intent=intent[0],
                target=ids[0] if len(ids) == 1 else f"<{len(ids)} {what} detections: not one>",
            )
        elif kind == "ambiguous":
            expect = Expect(
                "clarification",
                reason="ambiguous",  # up to 5 of them are listed
                among=tuple(object_id(found, i) for i, f in enumerate(found) if f[0] in what),
            )
        else:
            expect = Expect("clarification", reason="not_found", question=what)
        out.append(
            Scenario(
                f"real photo {Path(image).name}: {text}", real_scene(found, w, h, text), [expect], ("real photos",)
            )
        )
    return out
