"""Issue #31 measured on real photos of people pointing: "pick up that one" through the gesture service's per-frame
path, vision's pipeline (YOLOX-Nano) and the fusion core, in process (testkit/pointing_people.py). Prints, per photo,
what vision saw, whether a pointing ray reached fusion, and what fusion answered; then how many answers were safe
(never a person or something "pick up" cannot apply to) and right or honest.

Usage: python -m benchmarks.pointing_people   (needs ../shared/ or HRI_SHARED, and the YOLOX-Nano model)
"""

from __future__ import annotations

import os
from pathlib import Path

from testkit.pointing_people import evaluate, report

ROOT = Path(__file__).resolve().parent.parent


def main() -> None:
    shared = Path(os.environ.get("HRI_SHARED") or ROOT.parent / "shared")
    model = Path(os.environ.get("HRI_YOLOX_MODEL") or shared / "models" / "yolox_nano.onnx")
    print(report(evaluate(shared, model)))


if __name__ == "__main__":
    main()
