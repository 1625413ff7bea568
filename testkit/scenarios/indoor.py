"""The real indoor scenes of ../shared/data/scenes/ (photos + what a person says + the right answer), in process.

Each line of scenes.json: the photo goes through the vision service's own pipeline (`VisionPipeline` with the real
YOLOX-Nano `YoloDetector` at its defaults, colours by vision's colour model) and the sentence through `FusionCore`,
exactly as the services would run them, only without Zenoh. The result is judged against `expect`: the command's
target must overlap the expected box with IoU >= 0.5; an `ask` line must give a clarification whose candidates are
the expected boxes (as a set, each matched by IoU >= 0.5). tests/test_fusion_scenes_real.py runs these lines in
process and over Zenoh; benchmarks/fusion_eval.py prints them. Nothing of shared/ is copied: photos are read where
they are, upright as `cv2.imread` returns them (three photos carry an EXIF rotation; see the scenes README).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable

from common.boxes import iou
from common.schema import Clarification, DetectedObject, FusedCommand, ImageQuality
from testkit.images import read_image
from testkit.scenarios import Scenario, Step, by_time, detections_at, pointing, run_in_process, say

if TYPE_CHECKING:
    from services.vision.yolo import YoloDetector

IOU_MATCH = 0.5
SCENES = "data/scenes"


@dataclass(frozen=True)
class Line:
    photo: str
    say: str
    expect: dict[str, Any]
    note: str

    @property
    def name(self) -> str:
        return f"{self.photo}: {self.say}"


def load_lines(folder: Path) -> list[Line]:
    data = json.loads((folder / "scenes.json").read_text())
    return [Line(d["photo"], d["say"], d["expect"], d.get("note", "")) for d in data]


@dataclass(frozen=True)
class Seen:
    """One photo as vision sees it: what the vision service would publish for it."""

    objects: list[DetectedObject]
    quality: ImageQuality
    width: int
    height: int


def vision_pipeline(model: Path, detector: YoloDetector | None = None) -> Callable[[Path], Seen]:
    """photo -> what the vision service publishes (its own pipeline on the upright photo, longest side <= 960);
    `detector`: another than the model's at vision's defaults (testkit/golden.py's, which rounds what it finds)."""
    import cv2

    from services.vision.core import VisionPipeline
    from services.vision.yolo import YoloDetector

    pipeline = VisionPipeline(detector or YoloDetector(str(model)))

    def see(path: Path) -> Seen:
        img = read_image(str(path))
        if img is None:
            raise FileNotFoundError(f"cannot read the photo {path}")
        h, w = img.shape[:2]
        s = min(1.0, 960 / max(h, w))
        if s < 1.0:
            img = cv2.resize(img, (int(w * s), int(h * s)))
        pipeline.new_scene()  # every photo is a new scene: fresh ids, colours measured
        objects, quality = pipeline.process("cam0", img)
        return Seen(objects, quality, img.shape[1], img.shape[0])

    return see


def scenario(line: Line, seen: Seen) -> Scenario:
    def frame(t: float) -> Step:
        return detections_at(t, seen.objects, seen.quality, seen.width, seen.height)

    steps = [frame(round(-1.5 + 0.2 * i, 6)) for i in range(21)] + pointing(None) + [say(0.0, 1.5, line.say)]
    return Scenario(line.name, by_time(steps), [])


def judge(line: Line, outputs: list[Any]) -> tuple[bool, str]:
    """(right?, what happened in words)."""
    out = next((o for o in outputs if isinstance(o, (FusedCommand, Clarification))), None)
    if out is None:
        return False, "nothing published"
    if isinstance(out, FusedCommand):
        got = (
            f"{out.intent} {out.target.label if out.target else None} "
            f"{[round(v) for v in out.target.bbox] if out.target else ''}"
        )
        if "target" in line.expect:
            ok = out.target is not None and iou(out.target.bbox, line.expect["target"]) >= IOU_MATCH
            return ok, got
        return False, got + " (expected a question)"
    got = f"asks ({out.reason}): {out.question}"
    if "ask" not in line.expect:
        return False, got
    boxes = [c.bbox for c in out.candidates]
    want = line.expect["ask"]
    ok = (
        len(boxes) == len(want)
        and all(any(iou(b, w) >= IOU_MATCH for b in boxes) for w in want)
        and all(any(iou(b, w) >= IOU_MATCH for w in want) for b in boxes)
    )
    return ok, got


def evaluate(lines: list[Line], see: Callable[[Path], Seen], folder: Path) -> list[tuple[Line, bool, str]]:
    cache: dict[str, Seen] = {}
    results = []
    for line in lines:
        if line.photo not in cache:
            cache[line.photo] = see(folder / line.photo)
        outputs = run_in_process(scenario(line, cache[line.photo]))
        ok, got = judge(line, outputs)
        results.append((line, ok, got))
    return results


def report(results: list[tuple[Line, bool, str]]) -> str:
    rows = [f"{'ok ' if ok else 'BAD'} {line.name!r:60} -> {got}" for line, ok, got in results]
    rows.append(f"{sum(ok for _, ok, _ in results)}/{len(results)} right")
    return "\n".join(rows)
