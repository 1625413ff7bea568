"""benchmarks/stack.py counts a gesture command on an intent clip against the clip's labels (issue #40): inside a
labelled deliberate wave or stop it was given, outside nobody gave it (../shared/data/intent/intent.json)."""

from __future__ import annotations

from benchmarks.stack import LABEL_TOLERANCE_S, clip_time, gesture_given, labelled_gestures
from testkit.shared import shared_path


def test_a_wave_inside_the_webcam_clips_labelled_waves_was_given_and_outside_nobody_gave_it() -> None:
    labelled, fps, frames = labelled_gestures(shared_path("data/intent/cat2_webcam_swipe_wave_thumbs.mp4"))
    assert fps > 0 and frames > 0
    start, end = min(s for s, _, i in labelled if i == "come_here"), max(e for _, e, i in labelled if i == "come_here")
    assert gesture_given("come_here", (start + end) / 2, labelled)
    assert not gesture_given("come_here", end + LABEL_TOLERANCE_S + 1.0, labelled)  # the thumbs
    assert not gesture_given("stop", (start + end) / 2, labelled)  # a wave is not a stop
    assert not gesture_given("come_here", None, labelled)


def test_a_talking_clip_has_no_labelled_gesture_and_the_looped_clips_time_comes_from_the_frame_seq() -> None:
    assert labelled_gestures(shared_path("data/intent/cat4_tango_1wrQ6_woman_seated.mp4"))[0] == []
    seqs = {100.0: 170, 100.033: 171}
    assert clip_time(100.03, seqs, 16.0, 160) == 11 / 16.0  # the second loop's 11th frame
    assert clip_time(105.0, seqs, 16.0, 160) is None  # no frame stamped near
