"""The person stage (issue #33) beside bare MediaPipe doing the same work, in one run, on the frames of a real
two-person clip (../shared/data/talking/comp_turns_*.mp4, decoded once before timing):

- bare: `FaceDetection.process` on the frame, then `Pose.process` (static images) on the crop of every face's
  region but one (the person the full-frame pose already sees), the same crops as the stage;
- stage: `PeopleStage.update` (face detection, regions, pose per region, the tracker, the hands' owners) on every
  frame (`--persons-every 1`);
- the rest of the gesture frame for scale: bare `Hands.process` + `Pose.process` (video mode) on the frame.

Prints ms per frame (median and p90) of each, the stage's ratio to the bare loop (goal >= 0.9x its frames/s) and
what `--persons-every 2` (the default) costs per frame on average; and the stage given the face stage's faces, with
the full-range face detection it runs since issue #40 (#34 had dropped it on those frames) timed alone.

`--photos` instead: the people found on ../shared/data/people_multi through the service's path
(testkit/people_photos.py), per photo, development and held back apart (issue #40).

Usage: python -m benchmarks.persons [--frames 150] [--clip comp_turns_bbaf2n_lbbc2a.mp4] [--photos]
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from pathlib import Path
from typing import Callable

import numpy as np

from services.gesture.landmarks import FaceDetector, HandLandmarker, PoseLandmarker, RegionPose
from services.gesture.people_stage import PeopleStage
from services.gesture.persons import Box, body_fits_face, crop_int, face_region
from testkit.frames import read_frames
from testkit.harness import ROOT

SHARED = Path(os.environ.get("HRI_SHARED") or ROOT.parent / "shared")


def timed(frames: list[np.ndarray], work: Callable[[np.ndarray], object]) -> list[float]:
    out = []
    for img in frames:
        t = time.perf_counter()
        work(img)
        out.append((time.perf_counter() - t) * 1000.0)
    return out


def summary(name: str, ms: list[float]) -> float:
    p50 = statistics.median(ms)
    p90 = sorted(ms)[int(0.9 * (len(ms) - 1))]
    print(f"{name:58s} {p50:7.1f} ms p50  {p90:7.1f} ms p90  ({1000.0 / p50:5.1f} frames/s)")
    return p50


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--frames", type=int, default=150)
    parser.add_argument("--clip", default="comp_turns_bbaf2n_lbbc2a.mp4")
    parser.add_argument("--photos", action="store_true", help="people found on the people_multi photos instead")
    args = parser.parse_args()
    if args.photos:
        print_photos()
        return
    clip = SHARED / "data" / "talking" / args.clip
    if not clip.exists():
        raise SystemExit(f"{clip} not found (../shared/ beside the checkout, or HRI_SHARED)")
    frames = read_frames(clip, args.frames)
    print(f"{len(frames)} frames of {clip.name} ({frames[0].shape[1]}x{frames[0].shape[0]})")
    faces, regions, main_pose = FaceDetector(), RegionPose(), PoseLandmarker()
    skeletons = [main_pose.detect(img) for img in frames]  # the gesture frame's own pose, not timed here
    by_frame = {id(img): s for img, s in zip(frames, skeletons)}

    def bare(img: np.ndarray) -> None:
        h, w = img.shape[:2]
        boxes = [b for b, _ in faces.detect(img)]
        skeleton = by_frame[id(img)]
        for k, face in enumerate(boxes):
            if skeleton is not None and body_fits_face(skeleton, face):
                continue
            region = face_region(face, boxes[:k] + boxes[k + 1 :], w, h)
            if region is not None:
                regions.detect(img, crop_int(region))

    stage = PeopleStage(every=1)
    stage_every2 = PeopleStage(every=2)
    for img in frames[:5]:  # warm-up of both graphs
        bare(img)
    stamp = {id(img): i / 25.0 for i, img in enumerate(frames)}
    # interleaved frame by frame: a load from elsewhere on the machine falls on both alike
    bare_times: list[float] = []
    stage_times: list[float] = []
    for img in frames:
        bare_times.extend(timed([img], bare))
        stage_times.extend(timed([img], lambda im: stage.update(stamp[id(im)], im, by_frame[id(im)], [])))
    bare_ms = summary("bare MediaPipe: face detection + pose per other face region", bare_times)
    stage_ms = summary("person stage, every frame (PeopleStage.update)", stage_times)
    every2 = timed(frames, lambda img: stage_every2.update(stamp[id(img)], img, by_frame[id(img)], []))
    print(f"{'person stage, --persons-every 2 (mean per frame)':58s} {statistics.fmean(every2):7.1f} ms mean")
    # issue #40: the stage runs its full-range face detection even on the frames the face stage gave it faces
    # (#34 skipped it there; Face Mesh misses faces beyond ~2 m); the face stage's boxes stood in for by the
    # detector's own, computed before timing
    given: dict[int, list[tuple[Box, str | None]]] = {
        id(img): [(b, None) for b, _ in faces.detect(img)] for img in frames
    }
    stage_given = PeopleStage(every=1)
    detector_times: list[float] = []
    given_times: list[float] = []
    for img in frames:
        detector_times.extend(timed([img], faces.detect))
        given_times.extend(
            timed([img], lambda im: stage_given.update(stamp[id(im)], im, by_frame[id(im)], [], faces=given[id(im)]))
        )
    summary("person stage given the face stage's faces (every frame)", given_times)
    detector_ms = summary("  of which full-range face detection (added by #40)", detector_times)
    print(f"{'  added per frame at --persons-every 2':58s} {detector_ms / 2:7.1f} ms")
    hands, pose = HandLandmarker(), PoseLandmarker()

    def rest(img: np.ndarray) -> None:
        hands.detect(img)
        pose.detect(img)

    summary("for scale: the frame's hands + full-frame pose (bare)", timed(frames, rest))
    print(f"stage / bare frames/s: {bare_ms / stage_ms:.2f}x (goal >= 0.9x)")


def print_photos() -> None:
    from testkit.people_photos import HELD_BACK, evaluate, totals

    folder = SHARED / "data" / "people_multi"
    if not folder.is_dir():
        raise SystemExit(f"{folder} not found (../shared/ beside the checkout, or HRI_SHARED)")
    results = evaluate(folder)
    for r in results:
        kept = " (held back)" if r.file in HELD_BACK else ""
        print(f"{r.file:40s} {len(r.found)} of {r.people} found {r.found}, {r.tracks} persons{kept}")
    for name, held_back in (("development", False), ("held back", True)):
        found, people = totals(results, held_back)
        print(f"{name}: {found} of {people} people found")


if __name__ == "__main__":
    main()
