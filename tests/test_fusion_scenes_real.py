"""End-to-end grounding on the real indoor scenes of ../shared/data/scenes/ (12 photos, 30 sentences, the right
answers), judged by testkit/scenarios/indoor.py: a command's target must overlap the expected box (IoU >= 0.5), an
`ask` line must be a question among the expected boxes.

- in process: the photo through the vision service's own pipeline (real YOLOX-Nano, vision's colours), the sentence
  through `FusionCore`; fast, used while developing and by benchmarks/fusion_eval.py;
- over Zenoh: camera -> vision -> fusion as real processes, each sentence published the way `hri say` publishes it;
  every line must get the same verdict as in process.

Measured: 29/30 right with the colour model and the relations (the one wrong line: "the plant in the grey stone
pot" — the pot is no detection of its own; see docs/fusion.md). The bound below sits under that with a margin.
Skipped with the reason when ../shared/ or onnxruntime is absent.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import pytest

from common.schema import Clarification, Detections, FusedCommand
from hri.cli import make_transcript
from testkit.harness import Client, ProcessGroup, requires_services
from testkit.images import read_image
from testkit.scenarios.indoor import SCENES, evaluate, judge, load_lines, report, vision_pipeline
from testkit.shared import shared_path, yolox_model
from testkit.words import words_end_over

DIALOGUE_TIMEOUT = 0.5  # s: each line is judged on its own, as in process
MIN_RIGHT = 27  # of 30; measured 29 (in process and over Zenoh, relations + colour model merged), margin 2 lines


@pytest.fixture(scope="module")
def folder() -> Path:
    return shared_path(SCENES)


@pytest.fixture(scope="module")
def in_process(folder):
    pytest.importorskip("onnxruntime")
    results = evaluate(load_lines(folder), vision_pipeline(yolox_model()), folder)
    print("\n" + report(results))
    return results


def test_the_indoor_scenes_in_process(in_process):
    right = sum(ok for _, ok, _ in in_process)
    assert right >= MIN_RIGHT, report(in_process)


def test_relation_lines_pick_the_head_noun_not_the_anchor(in_process):
    """ "the bottle next to the sink" is a bottle: no line with a relation acts on its anchor's kind."""
    from services.fusion.parse import parse

    for line, _ok, got in in_process:
        phrase = parse(line.say).obj
        if phrase.relations and got.split()[0] in ("pick_up", "bring", "look_at", "go_to"):
            assert phrase.label in got, (line.say, got)


# More relation words on the same real photos (written for this test from looking at the photos; the boxes are the
# detector's). A relation that contradicts the only candidate is a question, never that candidate.
RELATION_LINES = [
    ("airbnb2_sink2.jpg", "hand me the bottle to the left of the vase", {"target": [321, 167, 52, 120]}),
    ("airbnb2_sink2.jpg", "hand me the bottle to the right of the vase", {"not_found": True}),
    ("airbnb2_sink2.jpg", "the vase right of the bottle", {"target": [412, 201, 73, 97]}),
    ("airbnb2_sink2.jpg", "the vase under the plant", {"target": [412, 201, 73, 97]}),
    ("airbnb6_chair3.jpg", "bring me the vase on the table", {"target": [108, 163, 52, 53]}),
    ("airbnb6_chair3.jpg", "look at the chair at the back", {"target": [292, 117, 88, 75]}),
    ("airbnb6_chair3.jpg", "look at the chair in front of the table", {"target": [150, 151, 266, 418]}),
    ("airbnb1_cup1.jpg", "pick up the cup in front of the bottle", {"target": [228, 283, 77, 121]}),
    ("airbnb1_cup1.jpg", "pick up the cup behind the bottle", {"not_found": True}),
    ("airbnb7_oven1.jpg", "go to the oven right of the microwave", {"target": [52, 95, 378, 555]}),
    ("airbnb7_oven1.jpg", "go to the microwave to the left of the stove", {"target": [1, 91, 116, 108]}),
]


@pytest.mark.parametrize("photo,text,expect", RELATION_LINES, ids=[f"{p}: {t}" for p, t, _ in RELATION_LINES])
def test_relation_words_on_real_photos(folder, photo, text, expect):
    pytest.importorskip("onnxruntime")
    from testkit.scenarios import run_in_process
    from testkit.scenarios.indoor import Line, scenario

    line = Line(photo, text, expect, "")
    outputs = run_in_process(scenario(line, _seen(folder, photo)))
    if expect.get("not_found"):
        assert len(outputs) == 1 and isinstance(outputs[0], Clarification) and outputs[0].reason == "not_found", outputs
        assert ", but no " in outputs[0].question, outputs[0].question  # says which part did not fit
        return
    ok, got = judge(line, outputs)
    assert ok, got


_SEEN: dict[str, Any] = {}


def _seen(folder: Path, photo: str):
    if photo not in _SEEN:
        if "see" not in _SEEN:
            _SEEN["see"] = vision_pipeline(yolox_model())
        _SEEN[photo] = _SEEN["see"](folder / photo)
    return _SEEN[photo]


@pytest.mark.integration
@requires_services("camera", "vision", "fusion")
def test_the_indoor_scenes_over_zenoh(in_process, folder, tmp_path):
    """The real processes: a camera per photo (an upright PNG copy in tmp_path, so the three EXIF-rotated photos
    arrive upright and the pixels are the ones the in-process run saw), vision with the real model, fusion with a
    short dialogue timeout so that a question left open by one line is not answered by the next."""
    import cv2

    lines = [line for line, _, _ in in_process]
    verdicts = {line.name: (ok, got) for line, ok, got in in_process}
    group = ProcessGroup()
    client = None
    camera = None
    problems = []
    last_end = 0.0
    try:
        group.router()
        group.service("vision", "--backend", "onnx", "--model", str(yolox_model()))
        group.service("fusion", "--dialogue-timeout", str(DIALOGUE_TIMEOUT))
        client = Client(group.endpoint)
        client.wait_alive("vision", timeout=60)
        client.wait_alive("fusion", timeout=60)
        results = client.collect("hri/fusion/**")
        seen = client.collect("hri/vision/*/objects")
        for photo in dict.fromkeys(line.photo for line in lines):
            upright = tmp_path / (Path(photo).stem + ".png")
            cv2.imwrite(str(upright), read_image(str(folder / photo)))
            if camera is not None:
                camera.terminate()
            shown_from = time.time()  # this photo's frames are captured from now on; the last one's before
            camera = group.service("camera", "--source", str(upright), "--fps", "5", "--loop", "--encoding", "png")
            for line in (x for x in lines if x.photo == photo):
                # the words end on a frame of this photo such that fusion's window and vision's look-back hold
                # detections of this photo only, whatever vision's lag; they start after the last question expired
                said = words_end_over(
                    line.say,
                    seen,
                    lambda d, since=shown_from: isinstance(d, Detections) and d.stamp >= since,
                    f"detections of {photo} only",
                    lookback=True,
                    earliest_start=last_end + DIALOGUE_TIMEOUT + 0.2,
                )
                n = len([s for _, s in results.drain() if isinstance(s, (FusedCommand, Clarification))])
                last_end = said.stamp
                client.publish(
                    "hri/speech/kbd/transcript",
                    make_transcript(line.say, mic="kbd", end=last_end, confidence=0.95, source="test/kbd"),
                )
                out = results.wait(n + 1, timeout=30, where=lambda k, s: isinstance(s, (FusedCommand, Clarification)))
                ok, got = judge(line, [out[-1][1]])
                print(f"{'ok ' if ok else 'BAD'} {line.name!r:60} -> {got}")
                if (ok, got) != verdicts[line.name]:
                    problems.append(f"{line.name}: over Zenoh {got!r} ({ok}), in process {verdicts[line.name]}")
    finally:
        if client is not None:
            client.close()
        group.close()
    assert not problems, problems + [group.logs()]
