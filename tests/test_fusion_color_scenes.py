"""Colour lines of the real indoor scenes (../shared/data/scenes, a development set) end to end through the pure
cores: the real YOLOX-Nano detector, vision's colour model, fusion's parse, score and choose. Skips with the reason
when the shared material is absent. Lines that need a relation ("in front", "in the grey pot") belong to the
relation rules and are left out here; docs/fusion.md "Colour" lists every colour line's outcome."""

from __future__ import annotations

import json

import cv2
import pytest

from common.boxes import iou
from common.schema import Detections, Weights
from services.fusion.ground import choose, scene_objects, score
from services.fusion.parse import parse
from services.vision.core import VisionPipeline
from testkit.shared import shared_path, yolox_model

RELATION_WORDS = (" in front", " in the ", " next to ", " behind ", " between ")


def colour_lines():
    scenes = shared_path("data/scenes")
    lines = json.loads((scenes / "scenes.json").read_text())
    return scenes, [
        ln for ln in lines if parse(ln["say"]).obj.color and not any(w in f" {ln['say']} " for w in RELATION_WORDS)
    ]


@pytest.fixture(scope="module")
def pipeline():
    from services.vision.yolo import YoloDetector

    return VisionPipeline(YoloDetector(str(yolox_model())))


def test_colour_lines_of_real_scenes(pipeline):
    scenes, lines = colour_lines()
    assert len(lines) >= 8
    wrong = []
    for ln in lines:
        img = cv2.imread(str(scenes / ln["photo"]))  # upright: cv2 applies the EXIF orientation (scenes README)
        objects, quality = pipeline.process(ln["photo"], img)
        dets = Detections(
            source="vision/cam0",
            cam="cam0",
            stamp=1.0,
            seq=1,
            width=img.shape[1],
            height=img.shape[0],
            objects=objects,
            quality=quality,
        )
        phrase = parse(ln["say"]).obj
        choice = choose(
            phrase, score(phrase, scene_objects([dets]), None, Weights(speech=0.6, vision=0.4, gesture=0.0), ref=1.0)
        )
        expect = ln["expect"]
        if "target" in expect:
            ok = choice.kind == "target" and iou(choice.winner.obj.bbox, expect["target"]) >= 0.5
        else:  # asked among (at least) the expected candidates: a duplicate box of one of them may join
            asked = [c.obj.bbox for c in choice.candidates] if choice.kind == "ambiguous" else []
            ok = all(any(iou(box, want) >= 0.5 for box in asked) for want in expect["ask"])
        if not ok:
            wrong.append((ln["photo"], ln["say"], choice.kind, [(c.obj.name(), c.obj.lab) for c in choice.candidates]))
    assert not wrong, wrong
