"""Gesture CPU per frame, its distribution, with the paced stages staggered or each on the frames it is due
(issue #34, services/gesture/schedule.py, `--stagger` / `--no-stagger`), side by side in one run.

The gesture service's whole per-frame path (`GestureCore.process`, shipped defaults but for `stagger`) on the frames
of real clips, stamped as a 30 fps camera of which `--served` frames a second reach gesture (the stack serves it
~20 of 30), beside the bare MediaPipe hands + pose graphs on the same frames. CPU time (`time.process_time`, all the
process's threads) of each frame; the set-ups alternate, several rounds; per set-up the p50 / p90 / p99 / max of
the frames' CPU over all rounds, and the mean (the work is the same: the mean should not move). Frames decoded once.

Usage: python benchmarks/stagger.py [--clips NAME,NAME] [--frames 150] [--rounds 3] [--served 30]
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))  # this checkout's services, when run as `python benchmarks/stagger.py`

from benchmarks.pose_pacing import SHARED, clip_frames  # noqa: E402
from services.gesture.core import GestureCore, GestureSettings  # noqa: E402
from testkit.frames import bgr_frame  # noqa: E402

CLIPS = "real_single_vr1_cfr25.mp4,comp_turns_bbaf2n_lbbc2a.mp4"


def served_stamps(n: int, served: float, fps: float = 30.0) -> list[float]:
    """The source stamps of `n` frames of an `fps` camera of which `served` a second reach gesture (the rest are
    dropped as stale, evenly): 30 of 30 every frame, 20 of 30 two frames of three."""
    stamps: list[float] = []
    k = 0
    while len(stamps) < n:
        if int(k * served // fps) != int((k - 1) * served // fps):
            stamps.append(k / fps)
        k += 1
    return stamps


def service_frames(images: list[np.ndarray], stagger: bool, stamps: list[float]) -> list[float]:
    """CPU ms of each frame through the service's path."""
    core = GestureCore(GestureSettings(stagger=stagger), "gesture/bench", 2)
    frames = [bgr_frame(img, k, stamps[k], cam="bench", source="camera/bench") for k, img in enumerate(images)]
    out: list[float] = []
    try:
        for k, img in enumerate(images):
            t0 = time.process_time()
            core.process(frames[k], img, fresh=k == 0)
            out.append((time.process_time() - t0) * 1000.0)
    finally:
        core.close()
    return out[1:]  # the first frame builds the graphs of the person and face stages


def bare_frames(images: list[np.ndarray]) -> list[float]:
    """CPU ms of each frame through bare MediaPipe hands + pose (every frame)."""
    import cv2
    from mediapipe.python.solutions import hands as mp_hands, pose as mp_pose

    hands = mp_hands.Hands(static_image_mode=False, max_num_hands=2, model_complexity=0)
    pose = mp_pose.Pose(static_image_mode=False, model_complexity=1)
    out: list[float] = []
    try:
        for img in images:
            t0 = time.process_time()
            rgb = cv2.cvtColor(img, cv2.COLOR_BGR2RGB)
            hands.process(rgb)
            pose.process(rgb)
            out.append((time.process_time() - t0) * 1000.0)
    finally:
        hands.close()
        pose.close()
    return out[1:]


def summary(values: list[float]) -> str:
    a = np.asarray(values)
    p50, p90, p99 = (float(np.percentile(a, q)) for q in (50, 90, 99))
    return f"p50 {p50:5.1f}  p90 {p90:5.1f}  p99 {p99:5.1f}  max {float(a.max()):5.1f}  mean {float(a.mean()):5.1f} ms"


def compare(name: str, images: list[np.ndarray], rounds: int, served: float) -> None:
    stamps = served_stamps(len(images), served)
    results: dict[str, list[float]] = {"bare hands + pose": [], "independent (--no-stagger)": [], "staggered": []}
    for _ in range(rounds):  # alternated: drift from other work on the machine hits them alike
        results["bare hands + pose"] += bare_frames(images)
        results["independent (--no-stagger)"] += service_frames(images, False, stamps)
        results["staggered"] += service_frames(images, True, stamps)
    print(f"{name}: {len(images)} frames {images[0].shape[1]}x{images[0].shape[0]}, {served:g} of 30 fps served")
    for setup, values in results.items():
        print(f"  {setup:28s} {summary(values)}  ({len(values)} frames)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--clips", default=CLIPS, help="clips of ../shared/data/talking, comma-separated")
    parser.add_argument("--frames", type=int, default=150)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--served", type=float, default=30.0, help="frames a second of the 30 fps camera served")
    parser.add_argument("--side", type=int, default=480, help="frames fitted inside side x side px (default 480)")
    args = parser.parse_args()
    paths = [SHARED / "data" / "talking" / name for name in args.clips.split(",")]
    missing = [p for p in paths if not p.exists()]
    if missing:
        print(f"skipped: needs {missing[0]} (../shared; set HRI_SHARED)")
        return
    print(f"load average at start {os.getloadavg()[0]:.2f}")
    for path in paths:
        compare(path.name, clip_frames(path, args.frames, args.side), args.rounds, args.served)
    print(f"load average at end {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
