"""The photo sets and the judging of gestures on real photos, shared by tests/test_gesture_photos.py and
benchmarks/gesture.py: each photo goes through the service's whole per-frame path (lite hand model + pose, video
mode, the person stage every 2nd frame, the tracker with hand + body fusion and the other persons' skeletons),
shown for 6 frames like a camera holding still; what gesture *starts* is judged against the expected one. The
27-photo set (issue #23) is defined here and in docs/gesture.md.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Callable

from services.gesture.landmarks import HandLandmarker, PoseLandmarker
from services.gesture.people_stage import PeopleStage, other_skeletons
from services.gesture.temporal import GestureTracker
from testkit.harness import DATA
from testkit.images import read_image
from testkit.shared import shared_dir

OPENCV_DOC = Path("/usr/share/doc/opencv-doc/opencv4/html")
FRAMES = 6

# (where, file, expected start: "open_palm" / "point" / None, the pointing arm)
REPO_PHOTOS = [
    ("repo", "demo/stop.png", "open_palm", None),
    ("repo", "demo/pointing.png", "point", "right"),
    ("repo", "images/hands/handSrc.jpg", "open_palm", None),  # lying sideways on a table (see docs: no body in view)
    ("repo", "images/hands/Back_Projection_Theory0.jpg", "open_palm", None),
    ("repo", "images/hands/Histogram_Comparison_Source_1.jpg", "open_palm", None),
]
OPENCV_PHOTOS = [
    ("opencv-doc", "Back_Projection1_Source_Image.jpg", "open_palm", None),
    ("opencv-doc", "Back_Projection_Theory2.jpg", "open_palm", None),
    ("opencv-doc", "Histogram_Comparison_Source_0.jpg", "open_palm", None),
    ("opencv-doc", "Histogram_Comparison_Source_2.jpg", "open_palm", None),
    ("opencv-doc", "Hull_Original_Image.jpg", "open_palm", None),
    ("opencv-doc", "handDst.jpg", "open_palm", None),
    ("opencv-doc", "fileListImage.jpg", "open_palm", None),  # flat hand on a mouse, no body: like handSrc
    ("opencv-doc", "frame.jpg", None, None),  # fingers holding a bottle cap up to the camera
    ("opencv-doc", "screen_charuco.jpg", None, None),  # hands holding a calibration board
]
POINTING_PHOTOS = [
    ("pointing", name, "point", side)
    for name, side in [
        ("lowcam_man_image3_left_arm_to_image_left.jpeg", "left"),
        ("lowcam_man_image4_left_arm_to_image_right.jpeg", "left"),
        ("lowcam_man_image5_left_arm_raised_forward.jpeg", "left"),
        ("lowcam_man_image7_right_arm_to_floor.jpeg", "right"),
        ("lowcam_man_image8_right_arm_at_camera.jpeg", "right"),
        ("nico_table_f01_red_cube.jpg", "right"),
        ("nico_table_f05_yellow_cube.jpg", "right"),
        ("nico_table_f06_row_middle_yellow.jpg", "right"),
        ("nico_table_f07_green_cube.jpg", "right"),
        ("nico_table_f10_row_right_green.jpg", "right"),
        ("room_woman_0126_t2_right_arm_to_image_right.png", "right"),
        ("room_woman_0126_t3_right_arm_to_image_left.png", "right"),
        ("room_woman_0219_t6_left_arm_to_image_right.png", "left"),
    ]
]
HAND_PHOTOS_27 = REPO_PHOTOS + OPENCV_PHOTOS + POINTING_PHOTOS
# HaGRID label (file prefix, README in ../shared/data/people) -> the start the robot should see
PEOPLE_EXPECTED = {"four": "open_palm", "call": None, "rock": None, "none": None}


def photo_path(where: str, name: str) -> Path:
    if where == "repo":
        return DATA / name
    if where == "opencv-doc":
        return OPENCV_DOC / name
    return shared_dir() / "data" / where / name


def starts_on_photo(path: Path, frames: int = FRAMES) -> list[tuple[str, str]]:
    """(gesture, hand) of every gesture that starts while the photo is shown `frames` times, as the service does."""
    img = read_image(str(path))
    if img is None:
        raise FileNotFoundError(f"cannot read {path}")
    hands, pose, tracker = HandLandmarker("lite", video=True), PoseLandmarker(video=True), GestureTracker()
    people = PeopleStage(every=2)  # the service's default `--persons-every 2`: every person's own skeleton
    out = []
    try:
        for i in range(frames):
            found, skeleton = hands.detect(img), pose.detect(img)
            others = other_skeletons(people.update(i / 10, img, skeleton, found))
            _, events = tracker.update(i / 10, found, skeleton, (img.shape[1], img.shape[0]), None, others)
            out += [(e.gesture, e.hand) for e in events if e.phase == "start"]
    finally:
        hands.close()
        pose.close()
        people.close()
    return out


def judge(starts: list[tuple[str, str]], expected: str | None, side: str | None) -> dict[str, bool]:
    """right / missed_stop / phantom_point / false_stop for one photo."""
    stops = [s for s in starts if s[0] == "open_palm"]
    points = [s for s in starts if s[0] == "point"]
    want_points = [("point", side)] if expected == "point" else []
    return {
        "right": bool(stops) == (expected == "open_palm") and len(stops) <= 1 and points == want_points,
        "missed_stop": expected == "open_palm" and not stops,
        "phantom_point": any(p not in want_points for p in points) or len(points) > len(want_points),
        "false_stop": expected != "open_palm" and bool(stops),
    }


def evaluate(
    photos: Any, starts_of: Callable[[Path], list[tuple[str, str]]] = starts_on_photo
) -> dict[str, tuple[list[tuple[str, str]], dict[str, bool]]]:
    """name -> (starts, judgement) over photos whose file exists (`starts_of`: how a photo's starts are found)."""
    results = {}
    for where, name, expected, side in photos:
        path = photo_path(where, name)
        if path.exists():
            starts = starts_of(path)
            results[name] = (starts, judge(starts, expected, side))
    return results


def count(results, key) -> int:
    return sum(j[key] for _, j in results.values())
