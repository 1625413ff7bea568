"""Unit tests of fusion's grounding (services/fusion/ground.py): scoring by words and pointing, the choice, the
pointed location."""

from __future__ import annotations

import dataclasses
import random

import pytest

from common.language import canonical_label
from common.schema import Weights
from services.fusion.evidence import select_pointing
from services.fusion.ground import (
    MAX_CANDIDATES,
    SceneObject,
    choose,
    pointing_score,
    ray_point,
    scene_objects,
    score,
    shortlist,
)
from services.fusion.parse import parse
from testkit.fusion import EVEN, pointing_obs
from testkit.scenarios import BASE_STAMP, Obj, bbox_of, scene_of
from testkit.scenarios.suite import BLUE_CUP, CANDIES, TWO_CUPS


def _pointing_at(target, origin=(320.0, 470.0)):
    d = (target[0] - origin[0], target[1] - origin[1])
    return select_pointing([pointing_obs(BASE_STAMP + i * 0.1, d) for i in range(5)], BASE_STAMP + 0.2)


def test_grounding_by_colour_class_and_position():
    objs = scene_of(TWO_CUPS + [Obj("ball", "sports ball", "red", (320, 330))])
    for text, expected in (
        ("the red cup", "cup_red"),
        ("the blue one", "cup_blue"),
        ("the ball", "ball"),
        ("the cup on the right", "cup_blue"),
        ("the left cup", "cup_red"),
    ):
        phrase = parse(text).obj
        choice = choose(phrase, score(phrase, objs, None, EVEN))
        assert choice.kind == "target" and choice.winner.obj.id == expected, (text, choice)


def test_grounding_two_red_candies_is_ambiguous_and_unknown_colour_is_not_found():
    objs = scene_of(CANDIES)
    phrase = parse("the red candy").obj
    choice = choose(phrase, score(phrase, objs, None, EVEN))
    assert choice.kind == "ambiguous" and {c.obj.id for c in choice.candidates} == {"candy_01", "candy_02", "candy_03"}
    phrase = parse("the purple candy").obj
    assert choose(phrase, score(phrase, objs, None, EVEN)).kind == "not_found"


def test_pointing_score_prefers_the_object_on_the_ray_and_ignores_what_is_behind_the_hand():
    objs = scene_of(TWO_CUPS + [Obj("behind", "cup", "green", (320, 479))])
    p = _pointing_at(BLUE_CUP.center)
    g = {o.id: pointing_score(p, o)[0] for o in objs}
    assert g["cup_blue"] > 0.9 and g["cup_red"] < 0.01 and g["behind"] == 0.0


def test_conflict_is_resolved_by_the_dominant_side_or_asked():
    objs = scene_of(TWO_CUPS)
    phrase = parse("the red cup").obj
    p = _pointing_at(BLUE_CUP.center)
    clear = choose(phrase, score(phrase, objs, p, Weights(speech=0.35, vision=0.35, gesture=0.3)))
    assert clear.kind == "conflict"
    noisy = choose(phrase, score(phrase, objs, p, Weights(speech=0.1, vision=0.45, gesture=0.45)))
    assert noisy.kind == "target" and noisy.winner.obj.id == "cup_blue" and noisy.overruled == "speech"
    dark = choose(
        phrase,
        score(
            phrase, scene_of(TWO_CUPS, quality=0.05), p, Weights(speech=0.5, vision=0.02, gesture=0.48), ref=BASE_STAMP
        ),
    )
    assert dark.kind == "target" and dark.winner.obj.id == "cup_blue"


def test_ray_point_stays_inside_the_image():
    for target in ((320, 0), (0, 0), (639, 470), (100, 200)):
        p = _pointing_at(target)
        x, y = ray_point(p)
        assert 0 <= x <= 639 and 0 <= y <= 479


def test_the_pointing_hand_is_never_its_own_target():
    """A skin-coloured blob of the pointing finger lies right on the ray; the object beyond it is meant."""
    from common.schema import DetectedObject, Detections, ImageQuality, Weights
    from services.fusion.evidence import Pointing
    from services.fusion.ground import choose, scene_objects, score
    from services.fusion.parse import parse

    def obj(i, color, cx, cy):
        return DetectedObject(
            id=i, label="object", color=color, score=0.95, bbox=[cx - 20, cy - 20, 40, 40], center=[cx, cy]
        )

    det = Detections(
        stamp=10.0,
        source="v",
        seq=1,
        cam="cam0",
        width=640,
        height=480,
        objects=[obj("finger", "orange", 430, 167), obj("candy", "red", 548, 132)],
        quality=ImageQuality(brightness=0.6, contrast=0.5, sharpness=0.6),
    )
    pointing = Pointing(
        stamp=10.0,
        cam="cam0",
        hand="right",
        origin=(271.0, 186.0),
        direction=(0.981, -0.193),
        confidence=0.9,
        stability=1.0,
        spread_deg=0.0,
        n=10,
        width=640,
        height=480,
        hand_box=(60.0, 20.0, 495.0, 400.0),
    )
    weights = Weights(speech=0.4, vision=0.35, gesture=0.25)
    phrase = parse("pick up that one").obj
    ranked = score(phrase, scene_objects([det]), pointing, weights, ref=10.0)
    assert [c.obj.id for c in ranked][0] == "candy" and ranked[1].gesture == 0.0
    assert choose(phrase, ranked).kind == "target"
    without_box = Pointing(**{**pointing.__dict__, "hand_box": None})
    assert choose(phrase, score(phrase, scene_objects([det]), without_box, weights, ref=10.0)).kind == "ambiguous"


def test_the_vectorised_ray_step_gives_what_the_one_object_functions_give() -> None:
    """deictic_scores runs numpy over the image-plane objects (issue #34: 1000 objects); every object's G, angle
    and under-the-fingertip verdict must be those of pointing_score / under_fingertip, on scenes where the ray
    passes through boxes, grazes them, starts inside one, points away, and with and without a hand box."""
    import dataclasses
    import random

    from services.fusion.ground import ray_score, ray_scores, under_fingertip

    rng = random.Random(7)
    objs = [
        Obj(
            f"o{i}",
            "cup",
            "red",
            (rng.uniform(0, 640), rng.uniform(0, 480)),
            (rng.uniform(2, 120), rng.uniform(2, 120)),
            0.9,
        )
        for i in range(400)
    ]
    objects = scene_of(objs)
    checked_under = 0
    for trial in range(12):
        target = objects[trial]
        base = _pointing_at(target.center, origin=(rng.uniform(0, 640), rng.uniform(0, 480)))
        assert base is not None
        hand_box = (base.origin[0] - 30, base.origin[1] - 30, base.origin[0] + 30, base.origin[1] + 30)
        for p in (base, dataclasses.replace(base, hand_box=hand_box), dataclasses.replace(base, direction=(1.0, 0.0))):
            got, under = ray_scores(p, objects)
            for o in objects:
                one = ray_score(p, o)
                assert got[o.key].gesture == pytest.approx(one.gesture, abs=1e-12)
                assert (got[o.key].angle is None) == (one.angle is None) and got[o.key].rule == one.rule
                if one.angle is not None:
                    assert got[o.key].angle == pytest.approx(one.angle, abs=1e-9)
                expected = one.angle is not None and one.gesture > 0 and under_fingertip(p, o)
                assert (o.key in under) == expected, (o, p)
                checked_under += expected
    assert checked_under > 20  # the scenes do put objects under the fingertip


def _varied_scene(rng: random.Random, n: int) -> list[SceneObject]:
    """n objects of few labels and colours on a grid of few positions and sizes: many exact ties in words, place and
    ray (identical copies too), detection scores, image qualities and stamps varied (adaptive trust)."""
    labels, colours = ("cup", "bowl", "bottle", "person"), ("red", "blue", "green", None)
    objs = [
        Obj(
            f"o{i:03d}",
            rng.choice(labels),
            rng.choice(colours),
            (float(rng.randrange(20, 620, 40)), float(rng.randrange(20, 460, 40))),
            (float(rng.choice((20, 40, 80))), float(rng.choice((20, 40, 80)))),
            rng.choice((0.5, 0.7, 0.9)),
        )
        for i in range(n)
    ]
    return [
        dataclasses.replace(o, quality=rng.choice((0.5, 1.0)), stamp=BASE_STAMP + rng.choice((0.0, 0.4, 1.5)))
        for o in scene_of(objs)
    ]


def test_the_shortlist_decides_what_the_whole_ranking_decides() -> None:
    """`shortlist` builds only what `choose` reads of the ranking (issue #34: 1000 objects); on scenes full of ties,
    for plain, coloured, spatial, ordinal and relational words, with and without pointing (a hand ray, touching or
    not), adaptive or not, it is a part of `score`'s ranking in the same order and `choose` makes the same Choice."""
    rng = random.Random(11)
    phrases = (
        "the red cup",
        "that cup",
        "that one",
        "the bottle on the left",
        "the second cup from the left",
        "the blue cup next to the bowl",
        "the biggest green bottle",
        "the person",
    )
    checked = 0
    for trial in range(6):
        objects = _varied_scene(rng, 300)
        target = objects[trial * 7].center
        base = _pointing_at(target, origin=(rng.uniform(0, 640), 470.0))
        assert base is not None
        tip_box = (target[0] - 60.0, target[1] - 60.0, target[0] - 5.0, target[1] - 5.0)  # a finger at the target
        for p in (None, base, dataclasses.replace(base, hand_box=tip_box)):
            for text in phrases:
                phrase = parse(text).obj
                for adaptive in (True, False):
                    ref = BASE_STAMP + 0.3
                    whole = score(phrase, objects, p, EVEN, adaptive=adaptive, ref=ref)
                    short = shortlist(phrase, objects, p, EVEN, adaptive=adaptive, ref=ref)
                    assert len(short) < len(whole) // 2 or p is None, (text, len(short))
                    positions = [whole.index(s) for s in short]
                    assert positions == sorted(positions) and positions[: MAX_CANDIDATES + 1] == list(
                        range(MAX_CANDIDATES + 1)
                    )
                    assert choose(phrase, short) == choose(phrase, whole), (trial, text, p)
                    checked += 1
    assert checked == 6 * 3 * len(phrases) * 2


def test_scene_objects_are_the_objects_the_constructor_builds() -> None:
    """`scene_objects` fills each object's fields in one step (issue #34); every field, the key included, is what
    `SceneObject(...)` makes of the same wire object: with and without depth, measured colour and colour names."""
    from common.schema import ColorShare, Detections
    from testkit.scenarios import see

    _, det = see(0.0, [Obj("a", "cup", "red", (100.0, 120.0)), Obj("b", "dining table", None, (300.0, 200.0))]).build(
        BASE_STAMP
    )
    assert isinstance(det, Detections)
    det.cam, det.frame_id = "cam1", "cam1_optical"
    full = det.objects[1]
    full.position, full.extent, full.lab = [0.1, 0.2, 1.5], [0.3, 0.2, 0.1], [50.0, 40.0, 20.0]
    full.colors = [ColorShare(name="red", p=0.7), ColorShare(name="orange", p=0.3)]
    built = scene_objects([det])
    for o, b in zip(det.objects, built):
        expected = SceneObject(
            o.id,
            canonical_label(o.label),
            o.label,
            o.color,
            bbox_of(o),
            (o.center[0], o.center[1]),
            o.score,
            "cam1",
            det.width,
            det.height,
            det.stamp,
            b.quality,
            tuple(o.position) if o.position else None,  # type: ignore[arg-type]
            tuple(o.extent) if o.extent else None,  # type: ignore[arg-type]
            "cam1_optical",
            tuple(o.lab) if o.lab else None,  # type: ignore[arg-type]
            tuple((c.name, c.p) for c in o.colors),
        )
        assert vars(b) == vars(expected) and b == expected and b.key == ("cam1", o.id)
    assert built[1].label == canonical_label("dining table") and built[1].colors == (("red", 0.7), ("orange", 0.3))


def test_a_relations_anchors_are_what_scoring_the_anchor_words_finds() -> None:
    """`_anchor_fits` takes the matches and their order from the evidence, without a `Scored` each (issue #34): on
    scenes full of ties, the anchors and their order are those of `score` on the objects the anchor's words name."""
    from common.language import label_matches
    from services.fusion.ground import ANCHOR_WEIGHTS, _anchor_fits

    rng = random.Random(5)
    for trial in range(4):
        scene = _varied_scene(rng, 200)
        for text in ("the bowl", "the red bowl", "the bowl on the left", "the second bowl", "the green one"):
            anchor = parse(text).obj
            named = [o for o in scene if label_matches(anchor.label, o.label)]
            expected = [
                (s.obj, s.match)
                for s in score(anchor, named, None, ANCHOR_WEIGHTS, adaptive=False, scene=scene)
                if s.match >= 0.5
            ]
            assert _anchor_fits(anchor, scene) == expected and expected, (trial, text)


def test_the_evidence_arrays_are_the_scored_numbers_to_the_bit() -> None:
    """The shortlist and a relation's anchors rank by `_Evidence.arrays`; they equal each object's `Scored` exactly
    (the same float operations in the same order), with and without pointing, adaptive or not, stamps varied."""
    from services.fusion.ground import _evidence

    rng = random.Random(13)
    for trial in range(3):
        objects = _varied_scene(rng, 150)
        p = _pointing_at(objects[trial].center, origin=(rng.uniform(0, 640), 470.0))
        for pointing in (None, p):
            for text in ("the red cup", "that one on the left", "the bowl next to the bottle"):
                for adaptive in (True, False):
                    ev = _evidence(parse(text).obj, objects, pointing, EVEN, adaptive, BASE_STAMP + 0.7, objects)
                    m, s, total = ev.arrays()
                    one = [ev.scored(i) for i in range(len(objects))]
                    assert m.tolist() == [c.match for c in one]
                    assert s.tolist() == [c.speech for c in one]
                    assert total.tolist() == [c.total for c in one]
