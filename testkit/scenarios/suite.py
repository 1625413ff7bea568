"""The scenarios. Image 640x480; the person's hand is at the bottom centre (320, 470).

Default timing: the utterance runs over [0, 1.5] s (transcript published 0.2 s later), vision
samples every 0.2 s and hand frames every 0.1 s over [-1.5, 2.5] s, everything published in
source-time order unless a scenario says otherwise.
"""

from __future__ import annotations

import random

from testkit.scenarios import (
    DARK,
    Expect,
    Obj,
    Scenario,
    Step,
    by_time,
    gesture,
    hands,
    pointing,
    say,
    scene,
)

RED_CUP = Obj("cup_red", "cup", "red", (150, 300))
BLUE_CUP = Obj("cup_blue", "cup", "blue", (490, 300))
GREEN_CUP = Obj("cup_green", "cup", "green", (320, 200))
BALL = Obj("ball_1", "sports ball", "yellow", (320, 330), (40, 40))
BOTTLE = Obj("bottle_1", "bottle", "blue", (420, 220), (40, 110))
GLASS = Obj("glass_1", "wine glass", None, (230, 250), (40, 90))
BIG_BOX = Obj("box_big", "box", "grey", (160, 260), (180, 140))
SMALL_BOX = Obj("box_small", "box", "grey", (480, 260), (60, 50))
TWO_CUPS = [RED_CUP, BLUE_CUP]
# Open language: objects named by their detector label (COCO-80), as Whisper prints what people say.
BANANA = Obj("banana_1", "banana", "yellow", (200, 300), (110, 50))
APPLE = Obj("apple_1", "apple", "red", (440, 300), (60, 60))
LAPTOP = Obj("laptop_1", "laptop", "grey", (330, 220), (200, 130))
BOWL = Obj("bowl_1", "bowl", "white", (180, 320), (90, 50))
FRUIT = [BANANA, APPLE]
# A Smarties-like spread of candies (the demo's real photo): several per colour.
CANDIES = [
    Obj("candy_01", "candy", "red", (80, 120), (40, 40)),
    Obj("candy_02", "candy", "red", (330, 260), (40, 40)),
    Obj("candy_03", "candy", "red", (560, 400), (40, 40)),
    Obj("candy_04", "candy", "blue", (120, 380), (40, 40)),
    Obj("candy_05", "candy", "blue", (450, 110), (40, 40)),
    Obj("candy_06", "candy", "yellow", (250, 140), (40, 40)),
    Obj("candy_07", "candy", "green", (520, 250), (40, 40)),
    Obj("candy_08", "candy", "orange", (200, 320), (40, 40)),
]

# Issue 22: relations, touch, people. A desk: the table under a laptop the finger rests on (the hand is at (320, 470)).
TABLE = Obj("table_1", "dining table", "brown", (320, 400), (640, 180))
DESK_LAPTOP = Obj("laptop_t", "laptop", "black", (330, 430), (200, 120))
CHAIR = Obj("chair_1", "chair", "white", (60, 300), (110, 200))
NEAR_BOTTLE = Obj("bottle_near", "bottle", "green", (250, 300), (40, 110))  # beside BOWL
FAR_BOTTLE = Obj("bottle_far", "bottle", "green", (560, 200), (40, 110))
ROW = [
    Obj("cup_1", "cup", "white", (120, 300)),
    Obj("cup_2", "cup", "white", (320, 300)),
    Obj("cup_3", "cup", "white", (520, 300)),
]
WOMAN = Obj("person_1", "person", None, (520, 220), (150, 420))
MAN = Obj("person_2", "person", None, (110, 220), (150, 420))
STACKED = [
    Obj("cup_a", "cup", "red", (300, 200), (60, 80)),
    Obj("cup_b", "cup", "red", (320, 230), (60, 80)),
    Obj("laptop_s", "laptop", "grey", (200, 190), (100, 70)),
    Obj("sink_s", "sink", "white", (400, 260), (80, 60)),
]

ANSWER_AT = 6.0  # follow-up utterances start here (well inside the 10 s dialogue timeout)


def normal(
    objects: list[Obj],
    text: str,
    point_at=None,
    *,
    conf: float = 0.92,
    quality=None,
    active=(-10.0, 10.0),
    extra: list[Step] | None = None,
    **point_kw,
) -> list[Step]:
    """The common shape: a scene, a hand (pointing or not), one utterance; in source-time order."""
    steps = scene(objects, **({"quality": quality} if quality else {})) + pointing(point_at, active=active, **point_kw)
    return by_time(steps + [say(0.0, 1.5, text, conf=conf)] + (extra or []))


def answer(objects: list[Obj], text: str, point_at=None, at: float = ANSWER_AT, conf: float = 0.92) -> list[Step]:
    """A follow-up utterance at `at` with the same scene around it."""
    steps = scene(objects, at - 1.5, at + 2.5) + pointing(point_at, at - 1.5, at + 2.5)
    return by_time(steps + [say(at, at + 1.0, text, conf=conf)])


def cmd(intent, target=None, location=False, motion=None) -> Expect:
    return Expect("command", intent=intent, target=target, location=location, motion=motion)


def ask(reason, candidates=None, question=None) -> Expect:
    return Expect(
        "clarification",
        reason=reason,
        candidates=tuple(candidates) if candidates is not None else None,
        question=question,
    )


def shuffled(steps: list[Step], seed: int) -> list[Step]:
    """Out-of-order delivery: everything inside the window (up to the transcript) shuffled, then the rest
    in order. (A sample past the window end arriving before one inside it would close the window early:
    the watermark assumes each stream is in order once it has passed a window.)"""
    early = [s for s in steps if s.t <= 1.7]
    late = [s for s in steps if s.t > 1.7]
    random.Random(seed).shuffle(early)
    return early + late


S = Scenario
SCENARIOS: list[Scenario] = [
    # -- colour -----------------------------------------------------------------------------
    S("colour: the red cup", normal(TWO_CUPS, "pick up the red cup"), [cmd("pick_up", "cup_red")], ("colour",)),
    S("colour: the blue cup", normal(TWO_CUPS, "bring me the blue cup"), [cmd("bring", "cup_blue")], ("colour",)),
    S("colour synonym: crimson", normal(TWO_CUPS, "grab the crimson mug"), [cmd("pick_up", "cup_red")], ("colour",)),
    S("colour synonym: navy", normal(TWO_CUPS, "hand me the navy one"), [cmd("bring", "cup_blue")], ("colour",)),
    S(
        "colour among three",
        normal(TWO_CUPS + [GREEN_CUP], "pick up the green one"),
        [cmd("pick_up", "cup_green")],
        ("colour",),
    ),
    # -- class ------------------------------------------------------------------------------
    S("class: the ball", normal([RED_CUP, BALL], "pick up the ball"), [cmd("pick_up", "ball_1")], ("class",)),
    S("class: the bottle", normal([RED_CUP, BOTTLE, BALL], "fetch the bottle"), [cmd("bring", "bottle_1")], ("class",)),
    S(
        "class alias: wine glass is a cup",
        normal([GLASS, BALL], "give me the glass"),
        [cmd("bring", "glass_1")],
        ("class",),
    ),
    S(
        "class and colour: blue bottle not blue cup",
        normal([BLUE_CUP, BOTTLE], "pick up the blue bottle"),
        [cmd("pick_up", "bottle_1")],
        ("class",),
    ),
    S(
        "fuzzy ASR slips",
        normal([BLUE_CUP, BOTTLE, BALL], "grabb the bluue bottel"),
        [cmd("pick_up", "bottle_1")],
        ("class",),
    ),
    # -- position ---------------------------------------------------------------------------
    S(
        "position: the left cup",
        normal(TWO_CUPS, "pick up the cup on the left"),
        [cmd("pick_up", "cup_red")],
        ("position",),
    ),
    S("position: the right one", normal(TWO_CUPS, "take the right one"), [cmd("pick_up", "cup_blue")], ("position",)),
    S(
        "position: the middle cup",
        normal(TWO_CUPS + [Obj("cup_mid", "cup", "red", (330, 300))], "pick up the cup in the middle"),
        [cmd("pick_up", "cup_mid")],
        ("position",),
    ),
    S(
        "size: the biggest box",
        normal([BIG_BOX, SMALL_BOX], "bring me the biggest box"),
        [cmd("bring", "box_big")],
        ("position",),
    ),
    S(
        "size: the small box",
        normal([BIG_BOX, SMALL_BOX], "pick up the small box"),
        [cmd("pick_up", "box_small")],
        ("position",),
    ),
    S(
        "candies: the blue one on the left",
        normal(CANDIES, "pick up the blue one on the left"),
        [cmd("pick_up", "candy_04")],
        ("position", "candies"),
    ),
    S(
        "candies: the yellow candy",
        normal(CANDIES, "pick up the yellow candy"),
        [cmd("pick_up", "candy_06")],
        ("colour", "candies"),
    ),
    # -- pointing ---------------------------------------------------------------------------
    S(
        "pointing: that cup",
        normal(TWO_CUPS, "pick up that cup", BLUE_CUP.center),
        [cmd("pick_up", "cup_blue")],
        ("pointing",),
    ),
    S(
        "pointing: give me that",
        normal([RED_CUP, BALL, BLUE_CUP], "give me that", RED_CUP.center),
        [cmd("bring", "cup_red")],
        ("pointing",),
    ),
    S(
        "pointing: that one among candies",
        normal(CANDIES, "pick up that one", (520, 250)),
        [cmd("pick_up", "candy_07")],
        ("pointing", "candies"),
    ),
    S(
        "late gesture within the window",
        normal(TWO_CUPS, "pick up that cup", BLUE_CUP.center, active=(1.55, 1.8)),
        [cmd("pick_up", "cup_blue")],
        ("pointing", "timing"),
    ),
    S(
        "gesture before the window is not used",
        normal(TWO_CUPS, "pick up that cup", BLUE_CUP.center, active=(-1.5, -1.2)),
        [ask("ambiguous", ["cup_red", "cup_blue"])],
        ("pointing", "timing"),
    ),
    S(
        "pointing from a gesture event only",
        by_time(
            scene(TWO_CUPS)
            + pointing(None)
            + [say(0.0, 1.5, "bring me that cup"), gesture(1.0, "point", "hold", point_at=RED_CUP.center)]
        ),
        [cmd("bring", "cup_red")],
        ("pointing",),
    ),
    S(
        "go there: a location",
        normal(TWO_CUPS, "go there", (320, 100)),
        [cmd("go_to", None, location=True)],
        ("pointing", "location"),
    ),
    S(
        "put it there: a location",
        normal(TWO_CUPS, "put it there", BLUE_CUP.center),
        [cmd("put_down", None, location=True)],
        ("pointing", "location"),
    ),
    S(
        "look at that",
        normal([RED_CUP, BALL, BLUE_CUP], "look at that", BALL.center),
        [cmd("look_at", "ball_1")],
        ("pointing",),
    ),
    # -- conflicts --------------------------------------------------------------------------
    S(
        "conflict: says red, points blue",
        normal(TWO_CUPS, "pick up the red cup", BLUE_CUP.center),
        [ask("conflict", ["cup_red", "cup_blue"])],
        ("conflict",),
    ),
    S(
        "conflict: noisy speech, clear pointing",
        normal(TWO_CUPS, "pick up the red cup", BLUE_CUP.center, conf=0.35),
        [cmd("pick_up", "cup_blue")],
        ("conflict", "noisy_speech", "eval"),
    ),
    S(
        "conflict: dark frame, clear pointing",
        normal(TWO_CUPS, "pick up the red cup", BLUE_CUP.center, quality=DARK),
        [cmd("pick_up", "cup_blue")],
        ("conflict", "dark", "eval"),
    ),
    S(
        "conflict: clear speech, shaky weak pointing",
        normal(TWO_CUPS, "pick up the red cup", BLUE_CUP.center, jitter_deg=15.0, score=0.6, ray_conf=0.6),
        [cmd("pick_up", "cup_red")],
        ("conflict", "eval"),
    ),
    S(
        "agreement: says red, points red",
        normal(TWO_CUPS, "pick up the red cup", RED_CUP.center),
        [cmd("pick_up", "cup_red")],
        ("pointing", "eval"),
    ),
    # -- ambiguity and the dialogue ---------------------------------------------------------
    S(
        "ambiguous: two cups, no pointing",
        normal(TWO_CUPS, "pick up the cup"),
        [ask("ambiguous", ["cup_red", "cup_blue"])],
        ("dialogue",),
    ),
    S(
        "follow-up: the red one",
        normal(TWO_CUPS, "pick up the cup") + answer(TWO_CUPS, "the red one"),
        [ask("ambiguous"), cmd("pick_up", "cup_red")],
        ("dialogue",),
    ),
    S(
        "follow-up: the left one",
        normal(TWO_CUPS, "bring me a cup") + answer(TWO_CUPS, "the left one"),
        [ask("ambiguous"), cmd("bring", "cup_red")],
        ("dialogue",),
    ),
    S(
        "follow-up: pointing and that one",
        normal(TWO_CUPS, "pick up the cup") + answer(TWO_CUPS, "that one", BLUE_CUP.center),
        [ask("ambiguous"), cmd("pick_up", "cup_blue")],
        ("dialogue",),
    ),
    S(
        "follow-up: conflict resolved by colour",
        normal(TWO_CUPS, "pick up the red cup", BLUE_CUP.center) + answer(TWO_CUPS, "the blue one"),
        [ask("conflict"), cmd("pick_up", "cup_blue")],
        ("dialogue", "conflict"),
    ),
    S(
        "follow-up: no cancels",
        normal(TWO_CUPS, "pick up the cup") + answer(TWO_CUPS, "no"),
        [ask("ambiguous")],
        ("dialogue",),
    ),
    S(
        "follow-up after the dialogue timeout is ignored",
        normal(TWO_CUPS, "pick up the cup") + answer(TWO_CUPS, "the red one", at=20.0),
        [ask("ambiguous")],
        ("dialogue",),
    ),
    S(
        "a new command replaces the question",
        normal(TWO_CUPS, "pick up the cup") + answer(TWO_CUPS, "bring me the blue cup"),
        [ask("ambiguous"), cmd("bring", "cup_blue")],
        ("dialogue",),
    ),
    S(
        "candies: the red candy is ambiguous",
        normal(CANDIES, "pick up the red candy"),
        [ask("ambiguous", ["candy_01", "candy_02", "candy_03"])],
        ("dialogue", "candies"),
    ),
    # -- low confidence -----------------------------------------------------------------------
    S(
        "low confidence: confirm first",
        normal(TWO_CUPS, "pick up the red cup", conf=0.2),
        [ask("low_confidence")],
        ("confidence",),
    ),
    S(
        "low confidence then yes",
        normal(TWO_CUPS, "pick up the red cup", conf=0.2) + answer(TWO_CUPS, "yes"),
        [ask("low_confidence"), cmd("pick_up", "cup_red")],
        ("confidence", "dialogue"),
    ),
    # -- not found ------------------------------------------------------------------------------
    S("not found: no green cup", normal(TWO_CUPS, "pick up the green cup"), [ask("not_found")], ("not_found",)),
    S(
        "not found, then the red one",
        normal(TWO_CUPS, "pick up the green cup") + answer(TWO_CUPS, "the red one"),
        [ask("not_found"), cmd("pick_up", "cup_red")],
        ("not_found", "dialogue"),
    ),
    S(
        "fallback option: most confident detection",
        normal(
            [
                Obj("cup_red", "cup", "red", (150, 300), score=0.6),
                Obj("cup_blue", "cup", "blue", (490, 300), score=0.8),
            ],
            "pick up the green cup",
        ),
        [cmd("pick_up", "cup_blue")],
        ("not_found",),
        {"fallback_most_confident": True},
    ),
    # -- missing modalities -----------------------------------------------------------------------
    S(
        "vision dead: come here still works",
        by_time(pointing(None) + [say(0.0, 1.0, "come here")]),
        [cmd("come_here")],
        ("missing",),
    ),
    S(
        "vision dead: asks instead of guessing",
        by_time(pointing(None) + [say(0.0, 1.5, "pick up the red cup")]),
        [ask("not_found")],
        ("missing",),
    ),
    S(
        "gesture dead: one cup is enough",
        by_time(scene([BLUE_CUP]) + [say(0.0, 1.5, "pick up that cup")]),
        [cmd("pick_up", "cup_blue")],
        ("missing",),
    ),
    S("speech only: go to the kitchen", [say(0.0, 1.2, "go to the kitchen")], [cmd("go_to")], ("missing",)),
    # -- delivery -----------------------------------------------------------------------------------
    S(
        "out of order: shuffled inputs",
        shuffled(normal(TWO_CUPS, "pick up that cup", BLUE_CUP.center), seed=7),
        [cmd("pick_up", "cup_blue")],
        ("order",),
    ),
    S(
        "out of order: transcript before the window's frames",
        (
            lambda st: (
                [x for x in st if x.t < -1.0]
                + [x for x in st if x.what.startswith("say")]
                + [x for x in st if x.t >= -1.0 and not x.what.startswith("say")]
            )
        )(normal(TWO_CUPS, "give me that", RED_CUP.center)),
        [cmd("bring", "cup_red")],
        ("order",),
    ),
    S(
        "duplicate transcript gives one command",
        (lambda st: st + [say(0.0, 1.5, "pick up the red cup")])(normal(TWO_CUPS, "pick up the red cup")),
        [cmd("pick_up", "cup_red")],
        ("order",),
    ),
    # -- gestures without speech ---------------------------------------------------------------------
    S("open palm: stop at once", [gesture(0.5, "open_palm", "start")], [cmd("stop")], ("gesture",)),
    S(
        "open palm held: one stop",
        [
            gesture(0.5, "open_palm", "start"),
            gesture(0.8, "open_palm", "hold"),
            gesture(1.1, "open_palm", "hold"),
            gesture(1.3, "open_palm", "end"),
        ],
        [cmd("stop")],
        ("gesture",),
    ),
    S(
        "wave held a second: come here",
        [gesture(0.5, "wave", "start", duration=0.0)]
        + [gesture(0.5 + 0.1 * i, "wave", "hold", duration=0.1 * i) for i in range(1, 13)],
        [cmd("come_here")],
        ("gesture",),
    ),
    S("weak open palm is ignored", [gesture(0.5, "open_palm", "start", score=0.2)], [], ("gesture",)),
    S(
        "stop gesture during speech wins",
        by_time(
            scene(TWO_CUPS)
            + [s for s in pointing(None) if not 0.5 <= s.t <= 1.2]
            + [hands(t, show="open_palm") for t in (0.5, 0.6, 0.7, 0.8, 0.9, 1.0, 1.1, 1.2)]
            + [say(0.0, 1.5, "pick up the red cup"), gesture(0.9, "open_palm", "start")]
        ),
        [cmd("stop")],
        ("gesture", "safety"),
    ),
    # -- speech-only intents ------------------------------------------------------------------------
    S("speech: stop", normal(TWO_CUPS, "stop"), [cmd("stop")], ("speech",)),
    S("speech: hello", normal(TWO_CUPS, "hello robot"), [cmd("greet")], ("speech",)),
    S("speech: follow me", normal(TWO_CUPS, "follow me"), [cmd("follow")], ("speech",)),
    S("speech: not a command", normal(TWO_CUPS, "what a nice day"), [], ("speech",)),
    # -- open language (Whisper text: capitals, punctuation, digits) ---------------------------------
    S(
        "language: the banana beside an apple",
        normal(FRUIT, "Bring me the banana."),
        [cmd("bring", "banana_1")],
        ("language",),
    ),
    S(
        "language: the fruit is a question",
        normal(FRUIT, "Bring me the fruit."),
        [ask("ambiguous", ["banana_1", "apple_1"])],
        ("language", "dialogue"),
    ),
    S(
        "language: the fruit, then the apple",
        normal(FRUIT, "Bring me the fruit.") + answer(FRUIT, "The apple."),
        [ask("ambiguous"), cmd("bring", "apple_1")],
        ("language", "dialogue"),
    ),
    S(
        "language: a COCO label, the laptop",
        normal([LAPTOP, RED_CUP], "Pick up the laptop."),
        [cmd("pick_up", "laptop_1")],
        ("language",),
    ),
    S(
        "language: plural and politeness",
        normal([RED_CUP, BALL], "Um, could you grab the cups for me, please?"),
        [cmd("pick_up", "cup_red")],
        ("language",),
    ),
    S(
        "language: an unknown noun is said in the question",
        normal([BLUE_CUP, BOWL], "Hand me the blue pitcher, please."),
        [ask("not_found", question="I don't know what a pitcher is. I can see a white bowl and a blue cup. Which one")],
        ("language", "not_found"),
    ),
    S(
        "language: unknown noun, then the cup",
        normal([BLUE_CUP, BOWL], "Hand me the blue pitcher, please.") + answer([BLUE_CUP, BOWL], "The cup."),
        [ask("not_found"), cmd("bring", "cup_blue")],
        ("language", "dialogue"),
    ),
    S(
        "language: unknown noun and a clear point",
        normal([BLUE_CUP, BOWL], "Give me that pitcher.", BOWL.center),
        [cmd("bring", "bowl_1")],
        ("language", "pointing"),
    ),
    S(
        "language: self-correction",
        normal(TWO_CUPS, "Pick up the red, no, the blue cup."),
        [cmd("pick_up", "cup_blue")],
        ("language",),
    ),
    S(
        "language: disfluent and polite",
        normal(TWO_CUPS, "Uh, could you, um, please bring me the red cup for me? Thanks."),
        [cmd("bring", "cup_red")],
        ("language",),
    ),
    S(
        "motion: go forward ten meters",
        normal(TWO_CUPS, "Go forward ten meters."),
        [cmd("move", motion=("forward", 10.0, None))],
        ("motion",),
    ),
    S("motion: turn right", normal(TWO_CUPS, "Turn right."), [cmd("turn", motion=("right", None, 90.0))], ("motion",)),
    S(
        "motion: go left 2 steps",
        normal(TWO_CUPS, "Go left 2 steps."),
        [cmd("move", motion=("left", 1.0, None))],
        ("motion",),
    ),
    S(
        "motion: move back a bit",
        normal([], "Move back a bit."),
        [cmd("move", motion=("back", 0.25, None))],
        ("motion",),
    ),
    S(
        "dialogue: no, the other one after a command",
        normal(TWO_CUPS, "Pick up the red cup.") + answer(TWO_CUPS, "No, the other one."),
        [cmd("pick_up", "cup_red"), cmd("pick_up", "cup_blue")],
        ("dialogue", "language"),
    ),
    S(
        "dialogue: no, the blue one after a command",
        normal(TWO_CUPS, "Bring me the red cup.") + answer(TWO_CUPS, "No, the blue one."),
        [cmd("bring", "cup_red"), cmd("bring", "cup_blue")],
        ("dialogue", "language"),
    ),
    S(
        "dialogue: not that one, to a confirmation",
        normal(TWO_CUPS, "Pick up the red cup.", conf=0.2) + answer(TWO_CUPS, "Not that one."),
        [ask("low_confidence"), cmd("pick_up", "cup_blue")],
        ("dialogue", "language"),
    ),
    S(
        "relation: the bottle next to the bowl is a bottle",
        normal([BOWL, NEAR_BOTTLE, FAR_BOTTLE], "Pick up the bottle next to the bowl."),
        [cmd("pick_up", "bottle_near")],
        ("relation", "language"),
    ),
    S(
        "relation: the second cup from the left",
        normal(ROW, "Bring me the second cup from the left."),
        [cmd("bring", "cup_2")],
        ("relation", "position"),
    ),
    S(
        "relation: a bare reference is looked at",
        normal([BOWL, NEAR_BOTTLE, FAR_BOTTLE], "The bottle by the bowl."),
        [cmd("look_at", "bottle_near")],
        ("relation", "language"),
    ),
    S(
        "relation: the question names landmarks and the answer uses them",
        normal(STACKED, "Pick up the red cup.") + answer(STACKED, "The one by the sink."),
        [
            ask("ambiguous", ["cup_a", "cup_b"], "the one next to the laptop or the one next to the sink"),
            cmd("pick_up", "cup_b"),
        ],
        ("relation", "dialogue"),
    ),
    S(
        "touch: a finger on the laptop is the laptop, not the table",
        normal([TABLE, DESK_LAPTOP, CHAIR], "Look at that.", (330.0, 479.0)),
        [cmd("look_at", "laptop_t")],
        ("touch", "pointing"),
    ),
    S(
        "people: give it to her",
        normal([WOMAN, RED_CUP], "Give it to her."),
        [cmd("bring", "person_1")],
        ("people", "language"),
    ),
    S(
        "people: give it to her, pointing at one of two",
        normal([WOMAN, MAN, RED_CUP], "Give it to her.", WOMAN.center),
        [cmd("bring", "person_1")],
        ("people", "pointing"),
    ),
    S(
        "people: look at the man on the left",
        normal([WOMAN, MAN, RED_CUP], "Look at the man on the left."),
        [cmd("look_at", "person_2")],
        ("people", "position"),
    ),
    S(
        "language: the stool is a chair",
        normal([CHAIR, WOMAN], "Go to the stool."),
        [cmd("go_to", "chair_1")],
        ("language",),
    ),
    S(
        "dialogue: yes to a confirmation, Whisper style",
        normal(TWO_CUPS, "Pick up the red cup.", conf=0.2) + answer(TWO_CUPS, "Yes, please."),
        [ask("low_confidence"), cmd("pick_up", "cup_red")],
        ("dialogue", "language"),
    ),
    S(
        "a brief wave (hands moving while talking): no command",
        [gesture(0.5, "wave", "start", duration=0.0)]
        + [gesture(0.5 + 0.1 * i, "wave", "hold", duration=0.1 * i) for i in range(1, 6)]
        + [gesture(1.1, "wave", "end", duration=0.6)],
        [],
        ("gesture",),
    ),
]
