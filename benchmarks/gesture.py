"""Gesture: the service's per-frame path vs bare MediaPipe calls on the same frames, one run; and the body ray's
accuracy on real pointing photos.

1. Throughput on the same 640x480 real frames (hand photos from data/, plus the people photos of
   ../shared/data/people when present; decoded once, before timing), in three set-ups:
   - hands only: bare `Hands.process` vs HandLandmarker.detect + GestureTracker.update;
   - body only: bare `Pose.process` vs PoseLandmarker.detect + GestureTracker.update (arm rules, fusion);
   - both: bare `Hands.process` + `Pose.process` vs the service's whole per-frame path.
   Lite hand model, full pose model (the only one in the wheel), video mode. Target: service >= 0.9x the bare
   loop's frames/s in each.
2. End-to-end lag at 30 fps input into a real gesture process (body stage on): p50/p99 per slice (flat).
3. `--rays`: angular error of the two body rays (eyes -> fingertip vs forearm elbow -> fingertip) to the target
   pixels of ../shared/data/pointing (README there), on the arm that points.

4. `--photos`: the stops and points that start on every real photo (the 27 hand photos of issue #23, the 30
   people photos, as defined in tests/test_gesture_photos.py, and the 7 people_multi photos with the pointer its
   JSON names), per photo and counted, with the `fist` (grasp) starts beside them (issue #31: resting hands).

Usage: python benchmarks/gesture.py [--seconds 60] [--frames 300] [--rays] [--photos]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import time
from pathlib import Path

import cv2
import numpy as np

from common.schema import Hands
from services.gesture.body import arm, arm_ray
from services.gesture.landmarks import HandLandmarker, PoseLandmarker
from services.gesture.temporal import GestureTracker, angle_between
from testkit.harness import DATA, ROOT
from testkit.images import read_image
from testkit.lag import frame_lag, print_throughput

SHARED = Path(os.environ.get("HRI_SHARED") or ROOT.parent / "shared")

# ../shared/data/pointing: file -> (pointing arm, candidate targets it indicates). From its README; where the exact
# target is not labelled ("the cups to the image right") every candidate on that side is listed and the nearest in
# angle counts, for both rays alike.
POINTING_TARGETS = {
    "nico_table_f01_red_cube.jpg": ("right", [(195, 535)]),
    "nico_table_f05_yellow_cube.jpg": ("right", [(345, 523)]),
    "nico_table_f06_row_middle_yellow.jpg": ("right", [(426, 539)]),
    "nico_table_f07_green_cube.jpg": ("right", [(470, 528)]),
    "nico_table_f10_row_right_green.jpg": ("right", [(505, 538)]),
    "room_woman_0126_t2_right_arm_to_image_right.png": ("right", [(761, 478), (933, 518)]),
    "room_woman_0126_t3_right_arm_to_image_left.png": ("right", [(592, 485), (424, 521)]),
    "room_woman_0219_t6_left_arm_to_image_right.png": ("left", [(853, 474)]),
}


def frames() -> list:
    paths = [
        DATA / "demo" / "pointing.png",
        DATA / "demo" / "stop.png",
        *sorted((DATA / "images" / "hands").glob("*.jpg")),
    ]
    paths += sorted((SHARED / "data" / "people").glob("*.jpg"))[:12]
    return [cv2.resize(read_image(str(p)), (640, 480)) for p in paths]


def _loop(n: int, step) -> float:
    t0 = time.perf_counter()
    for i in range(n):
        step(i)
    return n / (time.perf_counter() - t0)


def throughput(images: list, n: int, repeats: int = 3) -> None:
    # each photo is shown for 10 frames in a row, as a camera would: MediaPipe tracks between frames
    sequence = [f for f in images for _ in range(10)]
    results: dict[str, tuple[list, list]] = {"hands only": ([], []), "body only": ([], []), "both": ([], [])}
    for _ in range(repeats):  # alternate so drift hits both alike
        _throughput_round(sequence, n, results)
    for name, (bare, service) in results.items():
        print_throughput(
            f"{name}: {n} frames 640x480 of real people and hands",
            "bare MediaPipe",
            bare,
            "gesture service path",
            service,
        )


def _throughput_round(sequence: list, n: int, results: dict[str, tuple[list, list]]) -> None:
    """One round of each pair (bare MediaPipe, the service path); appends frames per second to `results`."""
    from mediapipe.python.solutions import hands as mp_hands, pose as mp_pose

    size = (sequence[0].shape[1], sequence[0].shape[0])
    rgb = lambda i: cv2.cvtColor(sequence[i % len(sequence)], cv2.COLOR_BGR2RGB)  # noqa: E731
    bgr = lambda i: sequence[i % len(sequence)]  # noqa: E731
    hands = mp_hands.Hands(static_image_mode=False, max_num_hands=2, model_complexity=0)
    results["hands only"][0].append(_loop(n, lambda i: hands.process(rgb(i))))
    hands.close()
    landmarker, tracker = HandLandmarker("lite", 2), GestureTracker()
    results["hands only"][1].append(_loop(n, lambda i: tracker.update(i / 30.0, landmarker.detect(bgr(i)))))
    landmarker.close()

    pose = mp_pose.Pose(static_image_mode=False, model_complexity=1)
    results["body only"][0].append(_loop(n, lambda i: pose.process(rgb(i))))
    pose.close()
    poser, tracker = PoseLandmarker(), GestureTracker()
    results["body only"][1].append(_loop(n, lambda i: tracker.update(i / 30.0, [], poser.detect(bgr(i)), size)))
    poser.close()

    hands, pose = (
        mp_hands.Hands(static_image_mode=False, max_num_hands=2, model_complexity=0),
        mp_pose.Pose(static_image_mode=False, model_complexity=1),
    )

    def bare_both(i: int) -> None:
        image = rgb(i)
        hands.process(image)
        pose.process(image)

    results["both"][0].append(_loop(n, bare_both))
    hands.close()
    pose.close()
    landmarker, poser, tracker = HandLandmarker("lite", 2), PoseLandmarker(), GestureTracker()
    results["both"][1].append(
        _loop(n, lambda i: tracker.update(i / 30.0, landmarker.detect(bgr(i)), poser.detect(bgr(i)), size))
    )
    landmarker.close()
    poser.close()


def angle_to(origin, direction, target) -> float:
    """Degrees between a ray and the direction from its origin to `target`."""
    v = np.subtract(target, origin)
    return angle_between(direction, tuple(v / (float(np.linalg.norm(v)) or 1.0)))


def ray_errors() -> dict[str, dict[str, float | None]]:
    """file -> {"eyes": error in degrees or None, "forearm": ..., "eyes_used": bool} on the pointing arm."""
    poser = PoseLandmarker(video=False)
    out = {}
    try:
        for name, (side, targets) in POINTING_TARGETS.items():
            img = read_image(str(SHARED / "data" / "pointing" / name))
            if img is None:
                continue
            skeleton = poser.detect(img)
            row: dict[str, float | None] = {"eyes": None, "forearm": None, "eyes_used": False, "pointing": False}
            if skeleton is not None:
                row["pointing"] = arm(skeleton, side, img.shape[1], img.shape[0]).pointing
                for how in ("eyes", "forearm"):  # the ray of the pointing arm, whatever the rules say
                    ray, used = arm_ray(skeleton, side, img.shape[1], img.shape[0], how)
                    if ray is not None:
                        row[how] = min(angle_to(ray[0], ray[1], t) for t in targets)
                        row["eyes_used"] = row["eyes_used"] or used == "eyes"
            out[name] = row
    finally:
        poser.close()
    return out


def print_rays() -> None:
    for _ in (1,):
        errors = ray_errors()
        if not errors:
            print(f"no pointing photos under {SHARED / 'data' / 'pointing'}: set HRI_SHARED")
            return
        print("body ray error to the target, pose model full (degrees; '-' = no skeleton)")
        for name, row in errors.items():
            fmt = lambda v: "   -" if v is None else f"{v:5.1f}"  # noqa: E731
            print(
                f"  {name:50s} eyes->tip {fmt(row['eyes'])} ({'eyes' if row['eyes_used'] else 'forearm fallback'})"
                f"  forearm {fmt(row['forearm'])}  arm rules: {'pointing' if row['pointing'] else 'not pointing'}"
            )
        both = [r for r in errors.values() if r["eyes"] is not None and r["forearm"] is not None]
        if both:
            for how in ("eyes", "forearm"):
                vals = [v for r in both if (v := r[how]) is not None]
                print(
                    f"  {how:8s} mean {statistics.mean(vals):5.1f}  median {statistics.median(vals):5.1f}  "
                    f"over {len(vals)} photos"
                )


def print_photos() -> None:
    from testkit.gesture_photos import HAND_PHOTOS_27, PEOPLE_EXPECTED, count, evaluate

    people = sorted((SHARED / "data" / "people").glob("*.jpg"))
    sets: dict[str, list[tuple[str, str, str | None, str | None]]] = {"27 hand photos": list(HAND_PHOTOS_27)}
    for label in PEOPLE_EXPECTED:
        sets[f"people {label}"] = [
            ("people", p.name, PEOPLE_EXPECTED[label], None) for p in people if p.name.startswith(label + "_")
        ]
    sets["people_multi"] = people_multi_photos()
    for title, photos in sets.items():
        results = evaluate(photos)
        for name, (starts, judged) in results.items():
            flags = [k for k, v in judged.items() if v and k != "right"]
            print(f"  {'ok   ' if judged['right'] else 'WRONG'} {name[:48]:48s} {starts} {' '.join(flags)}")
        print(
            f"{title}: {count(results, 'right')} of {len(results)} right, {count(results, 'missed_stop')} stops "
            f"missed, {count(results, 'phantom_point')} phantom points, {count(results, 'false_stop')} false stops, "
            f"{sum(g == 'fist' for starts, _ in results.values() for g, _ in starts)} fist starts"
            f" ({len(photos) - len(results)} photos not found)"
        )


def people_multi_photos() -> list[tuple[str, str, str | None, str | None]]:
    """(where, file, expected, arm) of ../shared/data/people_multi: a point from the arm people_multi.json names."""
    path = SHARED / "data" / "people_multi" / "people_multi.json"
    if not path.exists():
        return []
    out: list[tuple[str, str, str | None, str | None]] = []
    for image in json.loads(path.read_text())["images"]:
        pointing = [p["pointing"] for p in image["people"] if p.get("pointing")]
        arm = pointing[0]["arm"].split()[0] if pointing else None  # "left (image right)" -> "left"
        out.append(("people_multi", image["file"], "point" if pointing else None, arm))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seconds", type=float, default=60.0, help="length of the lag run (default 60)")
    parser.add_argument("--frames", type=int, default=300, help="frames per throughput measurement (default 300)")
    parser.add_argument("--rays", action="store_true", help="only the body-ray accuracy on the pointing photos")
    parser.add_argument("--photos", action="store_true", help="only the stop/point counts on the real photos")
    args = parser.parse_args()
    if args.photos:
        print_photos()
        return
    if args.rays:
        print_rays()
        return
    images = frames()
    throughput(images, args.frames)
    frame_lag("gesture", [], "hri/gesture/bench/hands", Hands, images, args.seconds)


if __name__ == "__main__":
    main()
