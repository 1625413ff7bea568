"""Gesture CPU per frame with full-body pose at its own rate (issue #34, `--pose-max-rate`), side by side in one run.

The gesture service's whole per-frame path (`GestureCore.process`: hands, pose, the person stage, the face stage,
the tracker; the shipped defaults but for the pose rate) on the frames of a real clip, stamped as a 30 fps camera,
for each pose rate given, beside the bare MediaPipe hands + pose graphs on the same frames (the every-frame floor).
CPU time (`time.process_time`) per frame; the set-ups alternate, several rounds, so that drift from other work on
the machine hits them alike. Frames decoded once, before timing.

Usage: python benchmarks/pose_pacing.py [--clip PATH] [--frames 150] [--rounds 3] [--rates 0,15,10]
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))  # this checkout's services, when run as `python benchmarks/pose_pacing.py`

from services.gesture.core import GestureCore, GestureSettings  # noqa: E402
from testkit.frames import bgr_frame, read_frames  # noqa: E402

SHARED = Path(os.environ.get("HRI_SHARED") or ROOT.parent / "shared")
DEFAULT_CLIP = SHARED / "data" / "talking" / "real_single_vr1_cfr25.mp4"


def clip_frames(path: Path, n: int, side: int) -> list[np.ndarray]:
    """The clip's first `n` frames fitted inside side x side (as the camera's `--size 640x480` gives 480x480)."""
    out: list[np.ndarray] = []
    for img in read_frames(path, n):
        h, w = img.shape[:2]
        scale = side / max(h, w)
        out.append(np.ascontiguousarray(cv2.resize(img, (round(w * scale), round(h * scale)))))
    return out


def cpu_ms_per_frame(n: int, step: Callable[[int], object]) -> float:
    t0 = time.process_time()
    for i in range(n):
        step(i)
    return (time.process_time() - t0) * 1000.0 / n


def service_path(images: list[np.ndarray], pose_max_rate: float) -> float:
    core = GestureCore(GestureSettings(pose_max_rate=pose_max_rate), "gesture/bench", 2)
    frames = [bgr_frame(img, k, k / 30.0, cam="bench", source="camera/bench") for k, img in enumerate(images)]
    try:
        return cpu_ms_per_frame(len(images), lambda k: core.process(frames[k], images[k], fresh=k == 0))
    finally:
        core.close()


def bare(images: list[np.ndarray]) -> float:
    from mediapipe.python.solutions import hands as mp_hands, pose as mp_pose

    hands = mp_hands.Hands(static_image_mode=False, max_num_hands=2, model_complexity=0)
    pose = mp_pose.Pose(static_image_mode=False, model_complexity=1)

    def both(k: int) -> None:
        rgb = cv2.cvtColor(images[k], cv2.COLOR_BGR2RGB)
        hands.process(rgb)
        pose.process(rgb)

    try:
        return cpu_ms_per_frame(len(images), both)
    finally:
        hands.close()
        pose.close()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--clip", type=Path, default=DEFAULT_CLIP)
    parser.add_argument("--frames", type=int, default=150)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--rates", default="0,15,10", help="pose rates to compare (0 = every frame)")
    parser.add_argument("--side", type=int, default=480, help="frames fitted inside side x side px (default 480)")
    args = parser.parse_args()
    if not args.clip.exists():
        print(f"skipped: needs {args.clip} (../shared; set HRI_SHARED)")
        return
    images = clip_frames(args.clip, args.frames, args.side)
    rates = [float(r) for r in args.rates.split(",")]
    results: dict[str, list[float]] = {"bare hands + pose, every frame": []}
    results.update({f"service path, pose {'every frame' if r <= 0 else f'{r:g}/s'}": [] for r in rates})
    print(
        f"{len(images)} frames {images[0].shape[1]}x{images[0].shape[0]} of {args.clip.name}, 30 fps stamps; "
        f"load average at start {os.getloadavg()[0]:.2f}"
    )
    for rnd in range(args.rounds):  # alternated
        results["bare hands + pose, every frame"].append(bare(images))
        for r in rates:
            results[f"service path, pose {'every frame' if r <= 0 else f'{r:g}/s'}"].append(service_path(images, r))
        print(f"  round {rnd + 1}: " + ", ".join(f"{v[-1]:.1f}" for v in results.values()) + " ms CPU/frame")
    floor = statistics.median(results["bare hands + pose, every frame"])
    for name, values in results.items():
        med = statistics.median(values)
        print(
            f"{name:40s} CPU {med:5.1f} ms/frame (rounds {', '.join(f'{v:.1f}' for v in values)}), "
            f"{med / floor:.2f}x the bare every-frame graphs"
        )
    print(f"load average at end {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
