"""Issue #31 on real photos of people pointing (../shared/data/pointing and people_multi: rooms at 4-5 m with a
bystander, a table at arm's length, a low camera), through the gesture service's own per-frame path, vision's own
pipeline with the real YOLOX-Nano and the fusion core, "pick up that one" said while the photo is shown
(testkit/pointing_people.py). No command or question may ever propose a person or something "pick up" cannot apply to;
each must act on the object pointed at or ask honestly. Skipped without ../shared/. About 40 s."""

from __future__ import annotations

from testkit.pointing_people import PHOTOS, evaluate, report
from testkit.shared import shared_dir, shared_path, yolox_model

MIN_RIGHT_OR_HONEST = len(PHOTOS) - 2  # measured 15 of 15 (main before issue #31: 6, and 0 of 15 safe)


def test_pick_up_that_one_never_proposes_a_person_or_furniture_on_real_photos() -> None:
    shared_path("data/pointing")
    shared_path("data/people_multi")
    verdicts = evaluate(shared_dir(), yolox_model())
    table = report(verdicts)
    assert len(verdicts) == len(PHOTOS), table
    assert all(v.safe for v in verdicts), table
    assert sum(v.right for v in verdicts) >= MIN_RIGHT_OR_HONEST, table
