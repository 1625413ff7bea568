"""Record real body + hand landmark arrays for the resting-hand and foreshortened-arm tests
(tests/data/landmarks/real_bodies.json; issue #31).

Runs the service's own PoseLandmarker and HandLandmarker (lite, the service's default) on real photos from
../shared/ (which may not be committed: only the arrays are), one still image each. A crop (x0, y0, x1, y1) and an
upscale are applied first where the photo shows several people (MediaPipe Pose finds one: the crop picks whom).
Usage: HRI_SHARED=... python -m testkit.record_bodies [--out FILE]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import cv2
import numpy as np

from services.gesture.landmarks import HandLandmarker, PoseLandmarker
from testkit.shared import shared_dir

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "tests" / "data" / "landmarks" / "real_bodies.json"

# name -> (photo under shared/data/, crop or None, upscale, what it shows)
SOURCES: dict[str, tuple[str, tuple[int, int, int, int] | None, float, str]] = {
    "seated_hands_on_knees": (
        "people_multi/coco_val2014_000000000241.jpg",
        (0, 240, 210, 620),
        2.0,
        "the man seated on the couch (image left), both hands resting between his knees: a fist and a flat hand",
    ),
    "standing_fist_hanging": (
        "people_multi/coco_val2014_000000000241.jpg",
        (100, 0, 340, 640),
        1.0,
        "the standing man, his left hand hanging relaxed at his side (the lite model reads it as a fist)",
    ),
    "forearm_across_belly": (
        "people/none_00c84257-800d-4032-9e64-e47eb97005f5.jpg",
        None,
        1.0,
        "a woman, her right forearm held across her belly (elbow folded), her left hand raised (thumbs down)",
    ),
    "arm_at_camera": (
        "pointing/lowcam_man_image8_right_arm_at_camera.jpeg",
        None,
        1.0,
        "a man pointing his right arm straight at the camera (foreshortened in the image)",
    ),
}


def _image(rel: str, crop: tuple[int, int, int, int] | None, scale: float) -> np.ndarray:
    img = cv2.imread(str(shared_dir() / "data" / rel))
    if img is None:
        raise ValueError(f"{rel} cannot be read under {shared_dir()}/data")
    if crop is not None:
        x0, y0, x1, y1 = crop
        img = img[y0:y1, x0:x1]
    if scale != 1.0:
        img = cv2.resize(img, None, fx=scale, fy=scale, interpolation=cv2.INTER_CUBIC)
    return img


def record() -> dict[str, dict]:
    out = {}
    for name, (rel, crop, scale, what) in SOURCES.items():
        img = _image(rel, crop, scale)
        hands, pose = HandLandmarker("lite", video=False), PoseLandmarker(video=False)
        try:
            observations, skeleton = hands.detect(img), pose.detect(img)
        finally:
            hands.close()
            pose.close()
        if skeleton is None:
            raise ValueError(f"{name}: no skeleton found in {rel}")
        out[name] = {
            "source": f"../shared/data/{rel}",
            "crop": crop,
            "upscale": scale,
            "what": what,
            "width": int(img.shape[1]),
            "height": int(img.shape[0]),
            "pose": [[round(float(v), 2) for v in row] for row in skeleton],
            "hands": [
                {"hand": o.hand, "landmarks": [[round(float(v), 2) for v in row] for row in o.landmarks]}
                for o in observations
            ],
        }
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, default=OUT)
    args = parser.parse_args()
    args.out.write_text(json.dumps(record(), indent=1) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
