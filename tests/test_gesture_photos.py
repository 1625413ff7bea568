"""Real photos through the service's whole per-frame path (lite hand model + pose, video mode, the tracker with
hand + body fusion), each photo shown for 6 frames like a camera holding still: what gesture *starts*.

Issue #23's targets: no open palm missed, no phantom point, at least 26 of the 27 real hand photos right. The
27-photo set was not written down by the round that counted it, so it is defined in testkit/gesture_photos.py
(and in docs/gesture.md):
- the repo's 5: data/demo/stop.png, data/demo/pointing.png, data/images/hands/*.jpg (3);
- 9 more real hand photos from Debian's opencv-doc (the ones MediaPipe finds a hand in that are not drawings and
  not already in the repo, fileListImageUnDist.jpg left out as the same photo undistorted);
- the 13 real pointing photos of ../shared/data/pointing (README there: which arm points).
A photo is right when the stops and points that start are exactly the expected ones (a point: one stream, from
the named arm). Other classes (fist, thumbs-up) are reported, not counted: the targets are about stops and points.
The 30 HaGRID people photos of ../shared/data/people are counted per class beside it.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from testkit.gesture_photos import (
    HAND_PHOTOS_27,
    OPENCV_DOC,
    PEOPLE_EXPECTED,
    REPO_PHOTOS,
    count,
    evaluate,
    judge,
    starts_on_photo,
)
from testkit.shared import shared_path

_STARTS: dict[Path, list[tuple[str, str]]] = {}


def _starts_once(path: Path) -> list[tuple[str, str]]:
    """A photo's starts, found once for this module: the repo's 5 photos are among the 27 (each photo runs through
    fresh models, so its starts do not depend on which test asks first)."""
    if path not in _STARTS:
        _STARTS[path] = starts_on_photo(path)
    return _STARTS[path]


# -- the judging rule itself --------------------------------------------------------------------------------
def test_judge_counts_a_second_point_stream_and_a_wrong_arm_as_phantom_points():
    assert judge([("point", "right")], "point", "right") == {
        "right": True,
        "missed_stop": False,
        "phantom_point": False,
        "false_stop": False,
    }
    assert judge([("point", "right"), ("point", "right")], "point", "right")["phantom_point"]
    assert judge([("point", "left")], "point", "right")["phantom_point"]
    assert judge([("point", "right")], "open_palm", None) == {
        "right": False,
        "missed_stop": True,
        "phantom_point": True,
        "false_stop": False,
    }
    assert judge([("fist", "left")], None, None)["right"]


# -- the real photos ------------------------------------------------------------------------------------------
def test_the_repos_real_hand_photos_all_right():
    results = evaluate(REPO_PHOTOS, _starts_once)
    assert len(results) == 5
    assert [n for n, (_, j) in results.items() if not j["right"]] == [], results


def test_the_27_real_hand_photos():
    """Measured (docs/gesture.md): 26 of 27 right, no stop missed, no phantom point; the one miss is
    nico_table_f05 (no hand found and no skeleton: the head is out of frame). Before issue #23's fix: 25 of 27
    (a second, pose-only point stream beside the hand's in nico_table_f10). The bound on `right` is one below."""
    if not OPENCV_DOC.is_dir():
        pytest.skip(f"{OPENCV_DOC} not found: install Debian's opencv-doc (`apt-get install opencv-doc`)")
    shared_path("data/pointing")
    results = evaluate(HAND_PHOTOS_27, _starts_once)
    assert len(results) == 27
    wrong = {n: s for n, (s, j) in results.items() if not j["right"]}
    assert count(results, "missed_stop") == 0, wrong
    assert count(results, "phantom_point") == 0, wrong
    assert count(results, "right") >= 25, wrong
    # issue #31: a relaxed hand hanging at the side is no grasp (lowcam image5 started a `fist` before; 0 measured on
    # two runs since)
    fists = {n: s for n, (s, _) in results.items() if any(g == "fist" for g, _ in s)}
    assert fists == {}, fists


def test_the_shared_people_photos_per_class():
    """HaGRID people at 1-3 m: every raised 'four' hand MediaPipe finds is a stop; 'call me', rock and other signs
    start no stop and no point. Measured: four 8 of 8 stops (four_25bb…: no hand found at 4 m, the raised arm
    stops), call/rock/none 0 stops, 0 points in 22."""
    folder = shared_path("data/people")
    photos = [("people", p.name, PEOPLE_EXPECTED[p.name.split("_")[0]], None) for p in sorted(folder.glob("*.jpg"))]
    assert len(photos) == 30
    results = evaluate(photos)
    four = {n: r for n, r in results.items() if n.startswith("four_")}
    signs = {n: r for n, r in results.items() if not n.startswith("four_")}
    assert count(four, "right") >= 7, four
    assert count(results, "phantom_point") == 0, results
    assert count(signs, "false_stop") <= 1, signs
    assert count(signs, "right") >= 21, signs
