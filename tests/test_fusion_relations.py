"""Relations between objects, ordinals, comparatives and touch (services/fusion/relations.py, touch.py, and their use
in ground.py): every relation word on boxes laid out as a table top is (a cup, a bowl, a laptop …), and the
fingertip inside one box, inside nested boxes and on an edge. The same rules on real photos:
tests/test_fusion_scenes_real.py."""

from __future__ import annotations

import pytest

from common import language as L
from common.schema import Weights
from services.fusion import relations as R, touch
from services.fusion.evidence import Pointing
from services.fusion.ground import choose, deictic_scores, score
from services.fusion.parse import parse
from testkit.scenarios import BASE_STAMP, Obj, scene_of

EVEN = Weights(speech=0.4, vision=0.2, gesture=0.4)
SPEECH = Weights(speech=1.0, vision=0.0, gesture=0.0)


def _pick(text, objs, weights=SPEECH):
    phrase = parse(text).obj
    return choose(phrase, score(phrase, objs, None, weights))


# A counter seen from the front: two bottles, two cups, a bowl, a laptop, a sink. Lower in the image = nearer.
COUNTER = [
    Obj("bottle_l", "bottle", "green", (100, 250), (40, 100)),
    Obj("bowl", "bowl", "white", (220, 300), (90, 50)),
    Obj("bottle_r", "bottle", "blue", (330, 300), (40, 100)),  # next to the bowl
    Obj("cup_back", "cup", "red", (470, 200), (40, 50)),  # far back (high in the image)
    Obj("cup_front", "cup", "red", (470, 400), (60, 70)),  # in front
    Obj("laptop", "laptop", "black", (590, 330), (90, 70)),
]


@pytest.mark.parametrize(
    "text,expected",
    [
        ("pick up the bottle next to the bowl", "bottle_r"),  # the head noun decides: a bottle, not the bowl
        ("pick up the bottle beside the bowl", "bottle_r"),
        ("pick up the bottle by the bowl", "bottle_r"),
        ("pick up the bottle near the bowl", "bottle_r"),
        ("pick up the bottle left of the bowl", "bottle_l"),
        ("pick up the bottle to the left of the bowl", "bottle_l"),
        ("pick up the bottle to the right of the bowl", "bottle_r"),
        ("pick up the cup behind the cup", "cup_back"),
        ("pick up the cup in front of the cup", "cup_front"),
        ("pick up the cup next to the laptop", "cup_front"),
        ("pick up the bowl between the two bottles", "bowl"),
        ("pick up the bottle between the bowl and the cup", "bottle_r"),
        ("pick up the second bottle from the left", "bottle_r"),
        ("pick up the first bottle from the right", "bottle_r"),
        ("pick up the last bottle", "bottle_r"),
        ("pick up the bigger cup", "cup_front"),
        ("pick up the smaller of the two cups", "cup_back"),
        ("pick up the cup in front", "cup_front"),
        ("pick up the cup at the back", "cup_back"),
    ],
)
def test_relation_words_pick_the_object_people_mean(text, expected):
    choice = _pick(text, scene_of(COUNTER))
    assert choice.kind == "target" and choice.winner.obj.id == expected, (
        text,
        choice.kind,
        [(c.obj.id, round(c.total, 3)) for c in choice.candidates],
    )


def test_support_and_containment_on_the_table_and_in_the_bowl():
    objs = scene_of(
        [
            Obj("table", "dining table", "brown", (320, 380), (600, 160)),
            Obj("cup_table", "cup", "white", (200, 330), (40, 50)),  # stands on the table top
            Obj("cup_shelf", "cup", "white", (500, 80), (40, 50)),  # on a shelf high above it
            Obj("bowl", "bowl", "white", (420, 340), (120, 60)),
            Obj("apple_bowl", "apple", "red", (420, 335), (30, 30)),
            Obj("apple_out", "apple", "red", (100, 340), (30, 30)),
        ]
    )
    for text, expected in (
        ("the cup on the table", "cup_table"),
        ("the apple in the bowl", "apple_in_bowl"),
        ("the cup on top of the table", "cup_table"),
        ("the apple inside the bowl", "apple_bowl"),
    ):
        expected = "apple_bowl" if expected == "apple_in_bowl" else expected
        choice = _pick(f"pick up {text}", objs)
        assert choice.kind == "target" and choice.winner.obj.id == expected, (text, choice)


def test_under_and_above():
    objs = scene_of(
        [
            Obj("shelf_book", "book", "red", (300, 100), (60, 40)),
            Obj("table", "dining table", None, (300, 250), (300, 80)),
            Obj("floor_book", "book", "blue", (300, 420), (60, 40)),
        ]
    )
    assert _pick("pick up the book under the table", objs).winner.obj.id == "floor_book"
    assert _pick("pick up the book above the table", objs).winner.obj.id == "shelf_book"


def test_two_objects_equally_next_to_the_anchor_are_a_question_and_a_missing_anchor_is_not_found():
    objs = scene_of(
        [
            Obj("cup_a", "cup", "red", (200, 300)),
            Obj("bowl", "bowl", None, (300, 300), (80, 50)),
            Obj("cup_b", "cup", "red", (400, 300)),
        ]
    )
    assert _pick("the cup next to the bowl", objs).kind == "ambiguous"
    assert _pick("the cup next to the laptop", objs).kind == "not_found"
    unknown = _pick("the cup next to the kettle", objs)
    assert unknown.kind == "not_found" and parse("the cup next to the kettle").obj.unknown_nouns == ("kettle",)


def test_relation_rules_on_their_own():
    cup, bowl = (100.0, 100.0, 40.0, 50.0), (150.0, 110.0, 80.0, 40.0)
    far = (500.0, 100.0, 40.0, 50.0)
    assert R.next_to(cup, bowl) > 0.8 and R.next_to(far, bowl) < 0.01  # a 10 px gap vs 270 px
    back, front = (300.0, 50.0, 40.0, 50.0), (300.0, 200.0, 40.0, 50.0)
    assert R.behind(back, front) > 0.95 and R.behind(front, back) < 0.05
    assert R.in_front_of(front, back) > 0.95 and R.in_front_of(back, front) < 0.05
    assert R.left_of(cup, bowl) > 0.9 > 0.1 > R.right_of(cup, bowl)
    assert R.in_((110.0, 120.0, 10.0, 10.0), bowl) == 0.0 and R.in_((160.0, 115.0, 20.0, 20.0), bowl) == 1.0
    assert R.between((300.0, 100.0, 20.0, 20.0), (100.0, 100.0, 20.0, 20.0), (500.0, 100.0, 20.0, 20.0)) > 0.9
    assert R.between((700.0, 100.0, 20.0, 20.0), (100.0, 100.0, 20.0, 20.0), (500.0, 100.0, 20.0, 20.0)) < 0.01
    assert R.relation_fit("between", cup, [bowl]) == 0.0  # one anchor is no pair
    assert set(R.RELATIONS) == set(R.PAIRWISE) | {"between"} == set(L.RELATION_PHRASES)


def test_every_relation_phrase_of_the_language_is_read_as_its_relation():
    for kind, phrases in L.RELATION_PHRASES.items():
        for words in phrases:
            u = parse(f"pick up the cup {words} the bowl")
            assert u.obj.label == "cup" and [r.kind for r in u.obj.relations] == [kind], (words, u.obj)
            assert u.obj.relations[0].anchors[0].label == "bowl", words


# -- touch ---------------------------------------------------------------------------------------------------------
def _body_ray_at(tip, direction=(0.0, 1.0)):
    """A body ray: it starts at the fingertip (docs/gesture.md)."""
    return Pointing(
        stamp=BASE_STAMP,
        cam="cam0",
        hand="right",
        origin=tip,
        direction=direction,
        confidence=0.9,
        stability=1.0,
        spread_deg=0.0,
        n=5,
        width=640,
        height=480,
    )


def _hand_ray(knuckle, direction, hand_box):
    return Pointing(
        stamp=BASE_STAMP,
        cam="cam0",
        hand="right",
        origin=knuckle,
        direction=direction,
        confidence=0.9,
        stability=1.0,
        spread_deg=0.0,
        n=5,
        width=640,
        height=480,
        hand_box=hand_box,
    )


DESK = [
    Obj("table", "dining table", "brown", (320, 330), (600, 260)),
    Obj("laptop", "laptop", "black", (300, 300), (200, 120)),
    Obj("chair", "chair", "white", (80, 330), (120, 200)),
    Obj("man", "person", None, (400, 200), (200, 400)),
]


def test_a_fingertip_on_the_keyboard_is_the_laptop_not_the_table_even_with_its_centre_behind_the_ray():
    objs = scene_of(DESK)
    # the finger points down-right onto the keyboard; the laptop's centre lies behind (up-left of) the tip
    p = _body_ray_at((330.0, 330.0), direction=(0.6, 0.8))
    g = deictic_scores(p, objs)
    assert g[("cam0", "laptop")][0] == 1.0 and g[("cam0", "table")][0] < 0.5 and g[("cam0", "man")][0] < 0.5
    phrase = parse("look at that").obj
    choice = choose(phrase, score(phrase, objs, p, EVEN))
    assert choice.kind == "target" and choice.winner.obj.id == "laptop"


def test_touch_with_a_hand_ray_uses_the_tip_where_the_ray_leaves_the_hand():
    objs = scene_of(
        [Obj("tray", "box", "grey", (300, 300), (240, 160)), Obj("cup", "cup", "white", (300, 300), (50, 60))]
    )
    # knuckle at (300, 240), finger straight down; the hand's landmarks end at y = 285: the tip is inside the cup
    p = _hand_ray((300.0, 240.0), (0.0, 1.0), (280.0, 200.0, 320.0, 285.0))
    assert touch.fingertip(p.origin, p.direction, p.hand_box) == pytest.approx((300.0, 285.0))
    g = deictic_scores(p, objs)
    assert g[("cam0", "cup")][0] == 1.0 and g[("cam0", "tray")][0] < 1.0


def test_touch_rules_on_boxes():
    table, laptop, cup = (0.0, 200.0, 600.0, 200.0), (100.0, 220.0, 200.0, 100.0), (400.0, 250.0, 40.0, 50.0)
    assert touch.touched((150.0, 250.0), [table, laptop, cup]) == ([1], [0])  # nested: the smallest wins
    assert touch.touched((500.0, 300.0), [table, laptop, cup]) == ([0], [])  # only the table holds the tip
    assert touch.touched((441.0, 260.0), [laptop, cup]) == ([1], [])  # on the cup's edge (within tolerance)
    assert touch.touched((460.0, 260.0), [laptop, cup]) == ([], [])  # clearly beside it
    side_by_side = [(100.0, 100.0, 50.0, 50.0), (148.0, 100.0, 50.0, 50.0)]
    assert touch.touched((149.0, 120.0), side_by_side) == ([0, 1], [])  # on the seam: both (the caller asks)


# -- people ---------------------------------------------------------------------------------------------------------
def test_people_are_objects_too():
    objs = scene_of(
        [
            Obj("woman", "person", None, (150, 240), (120, 400)),
            Obj("man", "person", None, (500, 240), (120, 400)),
            Obj("cup", "cup", "red", (320, 400)),
        ]
    )
    assert _pick("look at the man on the left", objs).winner.obj.id == "woman"  # "man": any person
    assert _pick("look at the person", objs).kind == "ambiguous"
    one = [o for o in objs if o.id != "man"]
    assert _pick("look at the person", one).winner.obj.id == "woman"
    u = parse("give it to her")
    assert u.intent == "bring" and u.obj.label == "person"
    assert choose(u.obj, score(u.obj, one, None, SPEECH)).winner.obj.id == "woman"
    assert parse("give her cup to me").obj.label == "cup"  # "her" before a noun is a determiner


def test_everyday_words_map_to_what_the_detector_names():
    for word, label in (
        ("stool", "chair"),
        ("armchair", "chair"),
        ("mug", "cup"),
        ("tumbler", "cup"),
        ("sofa", "couch"),
        ("screen", "tv"),
        ("monitor", "tv"),
        ("stove", "oven"),
    ):
        assert parse(f"bring me the {word}").obj.label == label, word
    assert L.label_matches(parse("bring me the flowers").obj.label, "vase")
    assert L.label_matches(parse("bring me the flowers").obj.label, "potted plant")
    assert L.label_matches(parse("bring me the glass").obj.label, "cup")
    assert L.label_matches(parse("bring me a seat").obj.label, "chair")


def test_a_modifier_nothing_can_check_is_said_back_never_dropped():
    phrase = parse("grab the soap bottle").obj
    assert phrase.label == "bottle" and phrase.unmatched == ("soap",) and phrase.describe() == "soap bottle"


# -- questions that help ----------------------------------------------------------------------------------------------
# Two red cups one behind the other ("left"/"right" would be a guess); one stands by the laptop, one by the sink.
CLUSTER = [
    Obj("cup_a", "cup", "red", (300, 200), (60, 80)),
    Obj("cup_b", "cup", "red", (320, 230), (60, 80)),
    Obj("laptop", "laptop", "grey", (200, 190), (100, 70)),
    Obj("sink", "sink", "white", (400, 260), (80, 60)),
]


@pytest.mark.parametrize(
    "answer,target",
    [("the one next to the laptop", "cup_a"), ("the one by the sink", "cup_b"), ("the cup beside the sink", "cup_b")],
)
def test_the_question_names_what_tells_the_cups_apart_and_those_words_answer_it(answer, target):
    from testkit.scenarios import Expect, Scenario, by_time, check, pointing, run_in_process, say, scene

    steps = (
        scene(CLUSTER, t1=6.0) + pointing(None, t1=6.0) + [say(0.0, 1.5, "pick up the red cup"), say(3.0, 4.5, answer)]
    )
    sc = Scenario(
        answer,
        by_time(steps),
        [
            Expect(
                "clarification",
                reason="ambiguous",
                candidates=("cup_a", "cup_b"),
                question="Which cup: the one next to the laptop or the one next to the sink?",
            ),
            Expect("command", intent="pick_up", target=target),
        ],
    )
    outputs = run_in_process(sc)
    assert not check(sc, outputs), check(sc, outputs)


def test_colours_and_positions_still_tell_apart_when_they_can():
    from services.fusion.describe import candidate_phrases

    objs = scene_of(
        [
            Obj("cup_red", "cup", "red", (100, 300)),
            Obj("cup_white", "cup", "white", (500, 300)),
            Obj("laptop", "laptop", "grey", (300, 300), (100, 70)),
        ]
    )
    assert candidate_phrases(objs[:2], objs) == ["the red one on the left", "the white one on the right"]


@pytest.mark.parametrize(
    "text,label,relations,spatial,place",
    [
        ("bring the cup next to the bowl to the kitchen", "cup", ["next to the bowl"], (), "kitchen"),
        ("bring me the plant on the table", "potted plant", ["on the dining table"], (), None),
        ("pick up the cup in the kitchen", "cup", [], (), "kitchen"),  # a place, not an object: no relation
        ("hand me the cup on your left", "cup", [], ("left",), None),
        ("hand me the bottle that is next to the sink on the right", "bottle", ["next to the sink"], ("right",), None),
        ("look at the chair in front", "chair", [], ("nearest",), None),
        ("look at the cup behind", "cup", [], ("farthest",), None),
        ("the stool on the far left", "chair", [], ("left",), None),
        ("put the cup on the table", "cup", [], (), "table"),  # put_down: the relation word starts the destination
    ],
)
def test_the_parser_splits_head_relations_and_places(text, label, relations, spatial, place):
    u = parse(text)
    assert (u.obj.label, [r.describe() for r in u.obj.relations], u.obj.spatial, u.place) == (
        label,
        relations,
        spatial,
        place,
    ), u


def test_a_ray_from_the_tip_touches_from_there_and_a_blob_on_the_hand_is_never_touched():
    """A body ray in a Hands frame starts at the fingertip, on the edge of the hand's box: the tip stays there."""
    objs = scene_of(
        [Obj("cup", "cup", "white", (300, 300), (50, 60)), Obj("tray", "box", "grey", (300, 330), (240, 160))]
    )
    ray = _hand_ray((300.0, 290.0), (0.0, 1.0), (290.0, 240.0, 310.0, 290.0))
    assert touch.fingertip(ray.origin, ray.direction, ray.hand_box) == pytest.approx((300.0, 290.0))
    assert deictic_scores(ray, objs)[("cam0", "cup")][0] == 1.0
    blob = scene_of([Obj("finger", "candy", "orange", (300, 280), (12, 12))])  # a skin blob on the hand itself
    assert deictic_scores(ray, objs + blob)[("cam0", "finger")][0] == 0.0


def test_a_self_correction_keeps_the_kind_and_takes_the_new_relation():
    u = parse("pick up the red cup, no, the one next to the bowl")
    assert (u.obj.label, u.obj.color, [r.describe() for r in u.obj.relations]) == ("cup", None, ["next to the bowl"])
    assert parse("pick up the red cup, no, the second one").obj.ordinal == 2


def test_a_second_box_on_part_of_an_object_is_not_another_candidate():
    """The detector boxes a chair and, again, its upper half (IoU under its NMS threshold): one chair, not two."""
    front = Obj("front", "chair", "green", (252, 444), (286, 462))
    top_half = Obj("top_half", "chair", "green", (235, 335), (262, 218))
    right = Obj("right", "chair", "green", (435, 340), (154, 325))
    choice = _pick("bring me the green chair", scene_of([front, top_half, right]))
    assert choice.kind == "ambiguous" and {c.obj.id for c in choice.candidates} == {"front", "right"}
    choice = _pick("bring me the green chair", scene_of([front, top_half]))
    assert choice.kind == "target" and choice.winner.obj.id == "front"
