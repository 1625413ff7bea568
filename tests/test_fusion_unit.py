"""Unit tests of fusion's functional core: parser, evidence, grounding, join, decisions (no zenoh)."""

from __future__ import annotations

import math
import random

import pytest

from common import language as L
from common.schema import Clarification, FusedCommand, ImageQuality, Weights
from services.fusion.core import Config, FusionCore, stable_id
from services.fusion.evidence import (
    PointingObs, image_quality, modality_weights, select_pointing, speech_reliability,
)
from services.fusion.ground import SceneObject, choose, pointing_score, ray_point, score
from services.fusion.join import Liveness, StreamBuffer, Streams, ready
from services.fusion.parse import ObjectPhrase, parse
from tests.scenarios import (
    BASE_STAMP, DARK, GOOD, Obj, by_time, check, gesture, pointing, run_in_process, say, scene,
)
from tests.scenarios.suite import BLUE_CUP, CANDIES, RED_CUP, SCENARIOS, TWO_CUPS, normal


# -- parser --------------------------------------------------------------------------------
@pytest.mark.parametrize("text,intent", [
    ("pick up the red cup", "pick_up"), ("grab it", "pick_up"), ("give me that", "bring"),
    ("hand me the bottle", "bring"), ("put it there", "put_down"), ("place the cup on the table", "put_down"),
    ("go there", "go_to"), ("come here", "come_here"), ("stop", "stop"), ("look at that", "look_at"),
    ("follow me", "follow"), ("hello robot", "greet"), ("please stop now", "stop"),
    ("could you bring me the yellow ball please", "bring"), ("pickup the ball", "pick_up"),
])
def test_parser_finds_the_intent(text, intent):
    assert parse(text).intent == intent


def test_parser_every_intent_phrase_of_the_language_is_understood():
    for intent, phrases in L.INTENT_PHRASES.items():
        for phrase in phrases:
            assert parse(phrase).intent == intent, phrase


@pytest.mark.parametrize("text,color,label,spatial", [
    ("pick up the crimson mug", "red", "cup", ()),
    ("bring me the navy bottle", "blue", "bottle", ()),
    ("take the blue one on the left", "blue", "object", ("left",)),
    ("the leftmost ball", None, "sports ball", ("left",)),
    ("grab the biggest box", None, "box", ("biggest",)),
    ("pick up the candy in the middle", None, "candy", ("middle",)),
    ("pick the nearest cup", None, "cup", ("nearest",)),
])
def test_parser_reads_the_object_phrase(text, color, label, spatial):
    obj = parse(text).obj
    assert (obj.color, obj.label, obj.spatial) == (color, label, spatial)


def test_parser_deixis_places_and_answers():
    u = parse("put it on the red box")
    assert u.obj.deictic and u.dest_obj == ObjectPhrase(color="red", label="box")
    assert parse("put the cup on the table").place == "table"
    assert parse("go there").deictic_place == "there"
    assert parse("pick up that cup").obj == ObjectPhrase(label="cup", deictic=True)
    assert parse("that one").obj.deictic and not parse("that one").obj.specific
    assert parse("yes").answer == "confirm" and parse("that is right").answer == "confirm"
    assert parse("no, the blue one").answer == "deny" and parse("no, the blue one").obj.color == "blue"
    assert parse("what a nice day").intent is None and not parse("what a nice day").has_content


def test_parser_corrects_asr_slips_but_not_into_a_stop():
    u = parse("grabb the bluue bottel")
    assert (u.intent, u.obj.color, u.obj.label) == ("pick_up", "blue", "bottle")
    assert len(u.corrections) == 3
    assert parse("I want the red cup").intent == "bring"  # a request, and "want" is not "wait" (= stop)
    assert parse("I want you to pick up the cup").intent == "pick_up"


# -- evidence --------------------------------------------------------------------------------
def _obs(t, direction, conf=0.9, cam="cam0"):
    n = math.hypot(*direction)
    return PointingObs(t, cam, "right", (320.0, 470.0), (direction[0] / n, direction[1] / n), conf, 640, 480)


def test_pointing_steady_ray_is_stable_and_shaky_ray_is_not():
    steady = select_pointing([_obs(1.0 + i * 0.1, (1, -1)) for i in range(6)], 1.2)
    shaky = select_pointing([_obs(1.0 + i * 0.1, (1, -1 + (0.6 if i % 2 else -0.6))) for i in range(6)], 1.2)
    assert steady.stability > 0.95 and shaky.stability < 0.3
    assert steady.reliability > shaky.reliability


def test_pointing_nearest_to_the_deictic_word_wins():
    obs = [_obs(0.0, (-1, -1)), _obs(3.0, (1, -1))]
    assert select_pointing(obs, 2.6).direction[0] > 0
    assert select_pointing(obs, 0.4).direction[0] < 0


def test_image_quality_and_weights():
    assert image_quality(ImageQuality(brightness=DARK[0], contrast=DARK[1], sharpness=DARK[2])) < 0.2
    assert image_quality(ImageQuality(brightness=GOOD[0], contrast=GOOD[1], sharpness=GOOD[2])) > 0.9
    w = modality_weights("adaptive", {"speech": 0.9, "vision": 0.1, "gesture": None})
    assert w.gesture == 0 and w.speech > w.vision and abs(w.speech + w.vision - 1) < 1e-3
    f1 = modality_weights("fixed", {"speech": 0.9, "vision": 0.1, "gesture": 0.5})
    f2 = modality_weights("fixed", {"speech": 0.1, "vision": 0.9, "gesture": 0.2})
    assert f1 == f2


def test_speech_reliability_follows_asr_confidence_and_corrections():
    _, low = say(0, 1, "pick up the red cup", conf=0.3).build(BASE_STAMP)
    _, high = say(0, 1, "pick up the red cup", conf=0.95).build(BASE_STAMP)
    _, slips = say(0, 1, "grabb the bluue bottel", conf=0.95).build(BASE_STAMP)
    assert speech_reliability(low, parse(low.text)) < speech_reliability(high, parse(high.text))
    assert speech_reliability(slips, parse(slips.text)) < speech_reliability(high, parse(high.text))


# -- grounding --------------------------------------------------------------------------------
def _scene(objs, quality=1.0):
    return [SceneObject(o.id, L.canonical_label(o.label), o.label, o.color,
                        tuple(o.detected().bbox), o.center, o.score, "cam0", 640, 480, BASE_STAMP, quality)
            for o in objs]


def _pointing_at(target, origin=(320.0, 470.0)):
    d = (target[0] - origin[0], target[1] - origin[1])
    return select_pointing([_obs(BASE_STAMP + i * 0.1, d) for i in range(5)], BASE_STAMP + 0.2)


EVEN = Weights(speech=0.4, vision=0.2, gesture=0.4)


def test_grounding_by_colour_class_and_position():
    objs = _scene(TWO_CUPS + [Obj("ball", "sports ball", "red", (320, 330))])
    for text, expected in (("the red cup", "cup_red"), ("the blue one", "cup_blue"), ("the ball", "ball"),
                           ("the cup on the right", "cup_blue"), ("the left cup", "cup_red")):
        phrase = parse(text).obj
        choice = choose(phrase, score(phrase, objs, None, EVEN))
        assert choice.kind == "target" and choice.winner.obj.id == expected, (text, choice)


def test_grounding_two_red_candies_is_ambiguous_and_unknown_colour_is_not_found():
    objs = _scene(CANDIES)
    phrase = parse("the red candy").obj
    choice = choose(phrase, score(phrase, objs, None, EVEN))
    assert choice.kind == "ambiguous" and {c.obj.id for c in choice.candidates} == {"candy_01", "candy_02", "candy_03"}
    phrase = parse("the purple candy").obj
    assert choose(phrase, score(phrase, objs, None, EVEN)).kind == "not_found"


def test_pointing_score_prefers_the_object_on_the_ray_and_ignores_what_is_behind_the_hand():
    objs = _scene(TWO_CUPS + [Obj("behind", "cup", "green", (320, 479))])
    p = _pointing_at(BLUE_CUP.center)
    g = {o.id: pointing_score(p, o)[0] for o in objs}
    assert g["cup_blue"] > 0.9 and g["cup_red"] < 0.01 and g["behind"] == 0.0


def test_conflict_is_resolved_by_the_dominant_side_or_asked():
    objs = _scene(TWO_CUPS)
    phrase = parse("the red cup").obj
    p = _pointing_at(BLUE_CUP.center)
    clear = choose(phrase, score(phrase, objs, p, Weights(speech=0.35, vision=0.35, gesture=0.3)))
    assert clear.kind == "conflict"
    noisy = choose(phrase, score(phrase, objs, p, Weights(speech=0.1, vision=0.45, gesture=0.45)))
    assert noisy.kind == "target" and noisy.winner.obj.id == "cup_blue" and noisy.overruled == "speech"
    dark = choose(phrase, score(phrase, _scene(TWO_CUPS, quality=0.05), p, Weights(speech=0.5, vision=0.02,
                                                                                  gesture=0.48), ref=BASE_STAMP))
    assert dark.kind == "target" and dark.winner.obj.id == "cup_blue"


def test_ray_point_stays_inside_the_image():
    for target in ((320, 0), (0, 0), (639, 470), (100, 200)):
        p = _pointing_at(target)
        x, y = ray_point(p)
        assert 0 <= x <= 639 and 0 <= y <= 479


# -- join -------------------------------------------------------------------------------------
def test_stream_buffer_orders_dedupes_and_stays_bounded():
    buf = StreamBuffer(horizon=5.0)
    for s in (3.0, 1.0, 2.0, 2.0):
        buf.add(s, s)
    assert buf.stamps == [1.0, 2.0, 3.0]
    assert buf.add(2.0, "again") == "duplicate"
    for i in range(1000):
        buf.add(1000.0 + i * 0.1, i)
    assert buf.stamps[0] >= buf.watermark - 5.0 and len(buf) <= 51
    assert buf.add(buf.watermark - 6.0, "old") == "late"
    restart = buf.watermark - 500.0
    verdicts = [buf.add(restart + 0.1 * i, "replay restarted") for i in range(buf.reset_run)]
    assert verdicts == ["late"] * (buf.reset_run - 1) + ["reset"] and len(buf) == 1
    assert buf.add(restart + 1.0, "new timeline") == "added" and buf.watermark == restart + 1.0


def test_stream_buffer_keeps_what_a_pending_window_needs():
    buf = StreamBuffer(horizon=5.0)
    buf.add(1.0, "needed")
    buf.add(100.0, "jump", keep_from=0.5)
    assert buf.between(0.0, 2.0) == ["needed"]


def test_ready_waits_for_live_watermarks_or_the_deadline():
    marks = {"vision": 10.0, "gesture": 9.0}
    assert ready(9.5, 0.0, 0.1, 0.5, marks, ["vision", "gesture"]) == (False, "")
    assert ready(9.5, 0.0, 0.1, 0.5, marks, ["vision"])[0]  # gesture not live: not waited for
    go, why = ready(9.5, 0.0, 0.6, 0.5, marks, ["vision", "gesture"])
    assert go and "gesture" in why


def test_liveness_token_or_recent_samples():
    live = Liveness(recent_s=2.0)
    assert not live.live("vision", 100.0)
    live.arrived("vision", 100.0)
    assert live.live("vision", 101.0) and not live.live("vision", 103.0)
    live.token("vision", "a", True)
    assert live.live("vision", 500.0)
    live.token("vision", "a", False)
    assert not live.live("vision", 500.0)


def test_a_vision_token_makes_fusion_wait_until_the_deadline():
    core = FusionCore(Config(max_wait=0.5), "fusion/test")
    core.on_liveliness("vision", "v1", True)
    key, t = say(0.0, 1.0, "hello").build(BASE_STAMP)
    core.on_transcript(key, t, 1000.0)
    assert core.tick(1000.1) == []
    (out,) = core.tick(1000.6)
    assert out.sample.intent == "greet" and out.sample.inputs["vision"] is None
    core.on_liveliness("vision", "v1", False)
    key, t = say(5.0, 6.0, "hello").build(BASE_STAMP)
    core.on_transcript(key, t, 1001.0)
    assert len(core.tick(1001.0)) == 1  # the token is gone: no waiting


def test_deadline_decides_with_what_is_there_and_says_what_is_missing():
    core = FusionCore(Config(max_wait=0.5), "fusion/test")
    for step in scene(TWO_CUPS, -1.5, 0.5):  # vision stalls before the utterance ends
        core.on_detections(*step.build(BASE_STAMP), 1000.0)
    key, t = say(0.0, 1.5, "pick up the red cup").build(BASE_STAMP)
    core.on_transcript(key, t, 1000.0)
    assert core.tick(1000.2) == []
    (out,) = core.tick(1000.6)
    assert out.sample.target.id == "cup_red" and "deadline" in out.sample.explanation


def interleaved(scenario, seed: int) -> list[int]:
    """A random interleaving of the per-key sequences: what the network may do (each key stays in order,
    keys overtake each other), plus a shuffle inside each key of what precedes the utterance."""
    per_key: dict[str, list[int]] = {}
    for i, step in enumerate(scenario.steps):
        per_key.setdefault(step.build(BASE_STAMP)[0], []).append(i)
    rng = random.Random(seed)
    for seq in per_key.values():
        early = [i for i in seq if scenario.steps[i].t < 0.0]
        rng.shuffle(early)
        seq[:len(early)] = early
    order, queues = [], [list(q) for q in per_key.values()]
    while any(queues):
        q = rng.choice([q for q in queues if q])
        order.append(q.pop(0))
    return order


@pytest.mark.parametrize("name", ["pointing: that cup", "follow-up: pointing and that one",
                                  "conflict: says red, points blue", "late gesture within the window",
                                  "candies: the blue one on the left", "stop gesture during speech wins",
                                  "out of order: shuffled inputs"])
def test_decisions_do_not_depend_on_delivery_order(name):
    scenario = next(s for s in SCENARIOS if s.name == name)
    reference = run_in_process(scenario)
    assert not check(scenario, reference)
    for seed in range(6):
        shuffled = run_in_process(scenario, order=interleaved(scenario, seed))
        assert [o.to_dict() for o in shuffled] == [o.to_dict() for o in reference], seed


def test_ids_are_deterministic_and_distinct():
    assert stable_id("cmd", "speech/mic0", 1.5, "mic0") == stable_id("cmd", "speech/mic0", 1.5, "mic0")
    assert stable_id("cmd", "speech/mic0", 1.5, "mic0") != stable_id("cmd", "speech/mic0", 1.6, "mic0")


# -- decisions ----------------------------------------------------------------------------------
def test_every_scenario_in_process():
    failures = {s.name: check(s, run_in_process(s)) for s in SCENARIOS}
    assert not {k: v for k, v in failures.items() if v}


def test_wrong_object_is_never_chosen_by_default_when_nothing_fits():
    scenario_steps = normal(TWO_CUPS, "pick up the green ball")
    from tests.scenarios import Scenario
    out = run_in_process(Scenario("x", scenario_steps, []))
    assert len(out) == 1 and isinstance(out[0], Clarification) and out[0].reason == "not_found"


def test_memory_stays_flat_over_a_long_stream():
    core = FusionCore(Config(), "fusion/test")
    sizes = []
    for second in range(600):
        base = BASE_STAMP + second
        for step in scene(TWO_CUPS, 0.0, 0.9, 0.1) + pointing(BLUE_CUP.center, 0.0, 0.9, 0.05):
            key, sample = step.build(base)
            (core.on_detections if key.endswith("objects") else core.on_hands)(key, sample, 1000.0 + second)
        if second % 10 == 0:
            key, t = say(0.2, 0.8, "pick up that cup").build(base)
            core.on_transcript(key, t, 1000.0 + second)
        core.tick(1000.0 + second + 1)
        sizes.append(core.memory_items())
    assert max(sizes[300:]) <= max(sizes[100:300]) + 5


def test_gesture_episode_gives_one_stop_and_a_new_episode_another():
    core = FusionCore(Config(), "fusion/test")
    outs = []
    for step in [gesture(0.5, "open_palm", "start"), gesture(0.8, "open_palm", "hold"),
                 gesture(1.0, "open_palm", "end"), gesture(5.0, "open_palm", "start")]:
        outs += core.on_gesture_event(*step.build(BASE_STAMP), 1000.0)
    assert [o.sample.intent for o in outs] == ["stop", "stop"] and all(o.realtime for o in outs)
    assert outs[0].sample.id != outs[1].sample.id


def test_prompt_lists_the_scene_and_is_bounded():
    many = [Obj(f"o{i}", "candy", "red", (5 + i * 0.6, 240), (4, 4), score=0.5 + i / 4000) for i in range(1000)]
    out = run_in_process(__import__("tests.scenarios", fromlist=["Scenario"]).Scenario(
        "many", by_time(scene(many, -1.0, 2.0, 0.5) + pointing(None) + [say(0.0, 1.5, "hello")]), []))
    (cmd,) = out
    assert isinstance(cmd, FusedCommand) and "Objects in view (1000, 25 most confident listed)" in cmd.prompt
    assert len(cmd.prompt.splitlines()) < 40


def test_named_places_are_published_in_the_command():
    from tests.scenarios import Scenario, run_in_process, say
    out = run_in_process(Scenario("place", [say(0.0, 1.2, "go to the kitchen")], []))
    (cmd,) = out
    assert cmd.intent == "go_to" and cmd.place == "kitchen" and cmd.location is None
    out = run_in_process(Scenario("no place", [say(0.0, 1.2, "come here")], []))
    assert out[0].place is None


def test_the_pointing_hand_is_never_its_own_target():
    """A skin-coloured blob of the pointing finger lies right on the ray; the object beyond it is meant."""
    from common.schema import DetectedObject, Detections, ImageQuality, Weights
    from services.fusion.evidence import Pointing
    from services.fusion.ground import choose, scene_objects, score
    from services.fusion.parse import parse

    def obj(i, color, cx, cy):
        return DetectedObject(id=i, label="object", color=color, score=0.95, bbox=[cx - 20, cy - 20, 40, 40],
                              center=[cx, cy])
    det = Detections(stamp=10.0, source="v", seq=1, cam="cam0", width=640, height=480,
                     objects=[obj("finger", "orange", 430, 167), obj("candy", "red", 548, 132)],
                     quality=ImageQuality(brightness=0.6, contrast=0.5, sharpness=0.6))
    pointing = Pointing(stamp=10.0, cam="cam0", hand="right", origin=(271.0, 186.0), direction=(0.981, -0.193),
                        confidence=0.9, stability=1.0, spread_deg=0.0, n=10, width=640, height=480,
                        hand_box=(60.0, 20.0, 495.0, 400.0))
    weights = Weights(speech=0.4, vision=0.35, gesture=0.25)
    phrase = parse("pick up that one").obj
    ranked = score(phrase, scene_objects([det]), pointing, weights, ref=10.0)
    assert [c.obj.id for c in ranked][0] == "candy" and ranked[1].gesture == 0.0
    assert choose(phrase, ranked).kind == "target"
    without_box = Pointing(**{**pointing.__dict__, "hand_box": None})
    assert choose(phrase, score(phrase, scene_objects([det]), without_box, weights, ref=10.0)).kind == "ambiguous"
