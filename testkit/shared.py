"""Material in ../shared/ (beside the checkout; CI always has it). It may never be committed, and a user who
clones the project has none: a test that needs it calls `shared_path` and skips with the reason when it is absent."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


def shared_dir() -> Path:
    """`$HRI_SHARED`, else the `shared/` folder beside the checkout."""
    return Path(os.environ.get("HRI_SHARED") or ROOT.parent / "shared")


def shared_path(relative: str) -> Path:
    """The path of `relative` under shared/, or skip the calling test saying what is missing and how to give it."""
    path = shared_dir() / relative
    if not path.exists():
        pytest.skip(
            f"{relative} not found under {shared_dir()} (it lives in ../shared/ beside the checkout; "
            f"set HRI_SHARED to that folder to run this test)"
        )
    return path


def yolox_model() -> Path:
    """The real YOLOX-Nano COCO detector: `$HRI_YOLOX_MODEL`, else shared/models/yolox_nano.onnx (or skip)."""
    env = os.environ.get("HRI_YOLOX_MODEL")
    if env:
        if not Path(env).is_file():
            pytest.skip(f"HRI_YOLOX_MODEL={env} is not a file")
        return Path(env)
    return shared_path("models/yolox_nano.onnx")
