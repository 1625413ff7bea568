"""Record the real landmark arrays the rule tests turn every way (tests/data/landmarks/real_hands.json).

Runs the service's own HandLandmarker on real photos, one still image at a time, with the full model (the more
accurate one: these arrays stand for "a real hand") and writes each hand's 21 [x, y] pixel landmarks.
Usage: python -m testkit.record_landmarks [--out FILE]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import cv2

from services.gesture.landmarks import HandLandmarker, LandmarkError

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "tests" / "data" / "landmarks" / "real_hands.json"

MODEL = "full"

# name -> photo (under data/): a pointing hand, an upright open palm, an open palm lying sideways
SOURCES = {
    "point_right": "demo/pointing.png",
    "open_palm_up": "demo/stop.png",
    "open_palm_sideways": "images/hands/handSrc.jpg",
}


def record(sources: dict[str, str] = SOURCES, data: Path = ROOT / "data") -> dict[str, dict]:
    """name -> {source, width, height, landmarks}; raises ValueError if a photo does not show exactly one hand."""
    landmarker = HandLandmarker(MODEL, max_hands=2, video=False)
    try:
        out = {}
        for name, rel in sources.items():
            img = cv2.imread(str(data / rel))
            if img is None:
                raise ValueError(f"{data / rel} cannot be read as an image")
            hands = landmarker.detect(img)
            if len(hands) != 1:
                raise ValueError(f"{rel}: expected one hand, MediaPipe found {len(hands)}")
            out[name] = {
                "source": Path(rel).name,
                "width": img.shape[1],
                "height": img.shape[0],
                "landmarks": [[round(x, 2), round(y, 2)] for x, y in hands[0].landmarks.tolist()],
            }
        return out
    finally:
        landmarker.close()


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, default=OUT, help=f"JSON file to write (default {OUT.relative_to(ROOT)})")
    args = parser.parse_args(argv)
    try:
        recorded = record()
    except (LandmarkError, ValueError) as exc:
        sys.exit(f"record_landmarks: {exc}")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(recorded, indent=1) + "\n")
    print(f"wrote {len(recorded)} hands to {args.out}")


if __name__ == "__main__":
    main()
