"""Persons on the real several-people photos (../shared/data/people_multi, people_multi.json there) through the
gesture service's whole per-frame path (`GestureCore` with its default settings: the face stage, the person stage
every 2nd frame, pose, hands), each photo shown for a few frames like a camera holding still; shared by
tests/test_gesture_persons_range.py and `python -m benchmarks.persons --photos` (issue #40).

A labelled person is **found** when a person of the stage's last run has a skeleton whose nose lies in that
person's labelled head box (grown by a fifth each side), or, without a skeleton, a face box whose centre does; each
person and each track counts once. The legs-only person of coco 241 has no head box and is never found.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from services.gesture.persons import PersonTrack
from testkit.images import read_image

FRAMES = 6  # the person stage runs on frames 0, 2 and 4
HELD_BACK = ("intel_walking_trio_f034.png", "room_pointer_bystander_0219_t21.png")  # BRIEF.md: measured, not tuned


@dataclass(frozen=True)
class PhotoPersons:
    file: str
    people: int  # labelled people (no DOG)
    found: list[str]  # the labelled ids found
    tracks: int  # persons the stage gave


def labelled(folder: Path) -> list[dict]:
    return json.loads((folder / "people_multi.json").read_text())["images"]


def _inside(point: np.ndarray, box: list[float], margin: float = 0.2) -> bool:
    x, y, w, h = box
    return bool(x - margin * w <= point[0] <= x + w + margin * w and y - margin * h <= point[1] <= y + h + margin * h)


def head_of(track: PersonTrack) -> np.ndarray | None:
    """Where the track's head is: its skeleton's nose, else its face box's centre."""
    if track.body is not None:
        return np.asarray(track.body[0, :2], dtype=float)
    if track.face_box is not None:
        x, y, w, h = track.face_box
        return np.array([x + w / 2, y + h / 2])
    return None


def found_people(image: dict, tracks: list[PersonTrack]) -> list[str]:
    """The labelled people of `image` that one track each stands for (first labelled, first served)."""
    heads = [head_of(t) for t in tracks]
    used: set[int] = set()
    out = []
    for person in image["people"]:
        if person["id"] == "DOG" or not person["head_box"]:
            continue
        k = next(
            (k for k, h in enumerate(heads) if k not in used and h is not None and _inside(h, person["head_box"])),
            None,
        )
        if k is not None:
            used.add(k)
            out.append(person["id"])
    return out


def persons_on_photo(path: Path, frames: int = FRAMES) -> list[PersonTrack]:
    """The persons of the person stage's last run while the photo is shown `frames` times at 10 fps."""
    from services.gesture.core import GestureCore, GestureSettings
    from testkit.frames import bgr_frame

    img = read_image(str(path))
    if img is None:
        raise FileNotFoundError(f"cannot read {path}")
    core = GestureCore(GestureSettings(), "gesture/test", depth_kept=2)
    last: list[PersonTrack] = []
    try:
        for k in range(frames):
            result = core.process(bgr_frame(img, k, k / 10), img, fresh=k == 0)
            if result.seen is not None and result.seen.ran:
                last = list(result.seen.persons)
    finally:
        core.close()
    return last


def evaluate(folder: Path) -> list[PhotoPersons]:
    out = []
    for image in labelled(folder):
        tracks = persons_on_photo(folder / image["file"])
        people = sum(p["id"] != "DOG" for p in image["people"])
        out.append(PhotoPersons(image["file"], people, found_people(image, tracks), len(tracks)))
    return out


def totals(results: list[PhotoPersons], held_back: bool) -> tuple[int, int]:
    """(found, labelled) over the development photos, or over the held-back ones."""
    chosen = [r for r in results if (r.file in HELD_BACK) == held_back]
    return sum(len(r.found) for r in chosen), sum(r.people for r in chosen)
