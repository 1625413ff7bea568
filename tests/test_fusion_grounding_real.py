"""Grounding by name on scenes made from the real YOLOX-Nano model's detections on real photos.

The detections are computed here with onnxruntime and the decoding of shared/models/MODEL.md (a small, local
decode: the vision service's own ONNX backend is tested in its own suite); the scene then goes through the
fusion core exactly as a Detections sample from the vision service would. Skipped with the reason when the
model (../shared/) is absent.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from common.language import COCO_LABELS
from common.schema import Clarification, DetectedObject, Detections, FusedCommand, ImageQuality
from services.fusion.core import Config
from tests.scenarios import KEYS, Expect, Scenario, Step, by_time, check, describe, pointing, run_in_process, say
from tests.shared import ROOT, shared_path, yolox_model

SIZE = 416
# The nano model's scores are moderate (a real cup at 0.30-0.32 in these photos); 0.25 keeps them with margin.
MIN_SCORE = 0.25
NMS_IOU = 0.45


@pytest.fixture(scope="module")
def detector():
    ort = pytest.importorskip("onnxruntime")
    cv2 = pytest.importorskip("cv2")
    session = ort.InferenceSession(str(yolox_model()), providers=["CPUExecutionProvider"])

    def detect(path: Path) -> tuple[list[tuple[str, float, list[float]]], int, int]:
        img = cv2.imread(str(path))
        assert img is not None, f"cannot read {path}"
        h, w = img.shape[:2]
        r = min(SIZE / h, SIZE / w)
        canvas = np.full((SIZE, SIZE, 3), 114, np.uint8)
        canvas[:int(h * r), :int(w * r)] = cv2.resize(img, (int(w * r), int(h * r)), interpolation=cv2.INTER_LINEAR)
        out = session.run(None, {"images": canvas.transpose(2, 0, 1)[None].astype(np.float32)})[0][0]
        grids = []
        for s in (8, 16, 32):
            gy, gx = np.mgrid[0:SIZE // s, 0:SIZE // s]
            grids.append(np.stack([gx.ravel(), gy.ravel(), np.full(gx.size, s)], 1))
        g = np.concatenate(grids).astype(np.float32)
        cx, cy = (out[:, 0] + g[:, 0]) * g[:, 2], (out[:, 1] + g[:, 1]) * g[:, 2]
        bw, bh = np.exp(out[:, 2]) * g[:, 2], np.exp(out[:, 3]) * g[:, 2]
        scores = out[:, 4:5] * out[:, 5:]
        cls, conf = scores.argmax(1), scores.max(1)
        keep = conf > MIN_SCORE
        x0 = np.clip((cx - bw / 2) / r, 0, w - 1)
        y0 = np.clip((cy - bh / 2) / r, 0, h - 1)
        x1 = np.clip((cx + bw / 2) / r, 0, w - 1)
        y1 = np.clip((cy + bh / 2) / r, 0, h - 1)
        boxes = np.stack([x0, y0, x1 - x0, y1 - y0], 1)[keep]
        idx = cv2.dnn.NMSBoxes(boxes.tolist(), conf[keep].tolist(), MIN_SCORE, NMS_IOU)
        found = [(COCO_LABELS[int(cls[keep][i])], float(conf[keep][i]), boxes[i].tolist())
                 for i in np.array(idx).ravel()]
        return found, w, h
    return detect


def photo(name: str) -> Path:
    if name.startswith("repo:"):
        return ROOT / name[5:]
    return shared_path(name)


def scene_steps(found, w: int, h: int, t0: float = -1.5, t1: float = 2.5) -> list[Step]:
    objects = [DetectedObject(id=f"{label.replace(' ', '_')}_{i}", label=label, color=None, score=round(score, 3),
                              bbox=box, center=[box[0] + box[2] / 2, box[1] + box[3] / 2])
               for i, (label, score, box) in enumerate(found)]

    def see(t: float) -> Step:
        def build(base: float):
            return KEYS.objects("cam0"), Detections(
                stamp=base + t, source="vision/cam0", seq=int(t * 10) + 1000, cam="cam0", width=w, height=h,
                objects=objects, quality=ImageQuality(brightness=0.5, contrast=0.5, sharpness=0.5))
        return Step(t, build, f"see {len(objects)} real detections")
    n = int(round((t1 - t0) / 0.2))
    return [see(round(t0 + i * 0.2, 6)) for i in range(n + 1)]


def ground(detector, image: str, text: str) -> tuple[list, list]:
    found, w, h = detector(photo(image))
    steps = by_time(scene_steps(found, w, h) + pointing(None) + [say(0.0, 1.5, text)])
    return run_in_process(Scenario(text, steps, []), Config()), found


CUP_PHOTO = "data/people/none_0a272153-56c7-42d5-a17d-cd307a1cd6d4.jpg"  # a person, a clock, a bottle, a cup
FRUIT_PHOTO = "repo:data/images/tabletop/smarties.png"  # candies the model takes for oranges, apples, frisbees
PERSON_PHOTO = "data/pointing/lowcam_man_image3_left_arm_to_image_left.jpeg"


@pytest.mark.parametrize("image,text,label", [
    (CUP_PHOTO, "Pick up the cup.", "cup"),
    (CUP_PHOTO, "Bring me the mug, please.", "cup"),
    (CUP_PHOTO, "Look at the person.", "person"),
    (CUP_PHOTO, "Could you, uh, fetch the bottle?", "bottle"),
    (PERSON_PHOTO, "Follow the person.", "person"),
    ("data/people/call_17b3aa02-dc4d-448d-8601-e2b67193d436.jpg", "Hand me the cup.", "cup"),
])
def test_a_named_object_is_grounded_on_the_real_detection(detector, image, text, label):
    outputs, found = ground(detector, image, text)
    assert len(outputs) == 1 and isinstance(outputs[0], FusedCommand), ([describe(o) for o in outputs], found)
    assert outputs[0].target.label == label, (describe(outputs[0]), found)


def test_the_fruit_among_several_fruits_is_a_question(detector):
    outputs, found = ground(detector, FRUIT_PHOTO, "Bring me the fruit.")
    fruit = {label for label, _, _ in found} & {"apple", "orange", "banana"}
    assert len([f for f in found if f[0] in fruit]) >= 2, found
    (out,) = outputs
    assert isinstance(out, Clarification) and out.reason == "ambiguous", describe(out)
    assert out.candidates and {c.label for c in out.candidates} <= {"apple", "orange", "banana"}, out.candidates
    assert "frisbee" not in out.question, out.question


def test_the_banana_is_not_an_apple_or_an_orange(detector):
    """The nano model finds no banana in these photos: the robot must say so, not act on another fruit."""
    outputs, found = ground(detector, FRUIT_PHOTO, "Bring me the banana.")
    assert "banana" not in {label for label, _, _ in found}, found
    (out,) = outputs
    assert isinstance(out, Clarification) and out.reason == "not_found", describe(out)
    assert out.question.startswith("I can't see the banana. I can see an "), out.question


def test_an_unknown_noun_is_said_in_the_question(detector):
    outputs, found = ground(detector, CUP_PHOTO, "Hand me the pitcher, please.")
    (out,) = outputs
    assert isinstance(out, Clarification) and out.reason == "not_found", describe(out)
    assert out.question.startswith("I don't know what a pitcher is. I can see ") and "a cup" in out.question, \
        out.question


def test_a_drink_is_the_bottle_or_the_cup(detector):
    outputs, found = ground(detector, CUP_PHOTO, "Give me a drink.")
    (out,) = outputs
    assert isinstance(out, Clarification) and out.reason == "ambiguous", describe(out)
    assert {c.label for c in out.candidates} == {"bottle", "cup"}, out.candidates


def test_expectations_hold_as_a_scenario(detector):
    """The same real scene through the scenario checker (what the suite uses)."""
    found, w, h = detector(photo(CUP_PHOTO))
    cup = next(f"{label}_{i}" for i, (label, _, _) in enumerate(found) if label == "cup")
    sc = Scenario("real: the cup", by_time(scene_steps(found, w, h) + pointing(None) + [say(0.0, 1.5, "Pick up the cup.")]),
                  [Expect("command", intent="pick_up", target=cup)])
    assert not check(sc, run_in_process(sc)), check(sc, run_in_process(sc))
