"""Unit tests of fusion's outputs (services/fusion/outputs.py): ids, the planner prompt, what a command carries."""

from __future__ import annotations

from common.schema import FusedCommand
from services.fusion.outputs import stable_id
from testkit.fusion import utterance, window
from testkit.scenarios import Obj, by_time, pointing, run_in_process, say, scene


def test_ids_are_deterministic_and_distinct():
    assert stable_id("cmd", "speech/mic0", 1.5, "mic0") == stable_id("cmd", "speech/mic0", 1.5, "mic0")
    assert stable_id("cmd", "speech/mic0", 1.5, "mic0") != stable_id("cmd", "speech/mic0", 1.6, "mic0")


def test_prompt_lists_the_scene_and_is_bounded():
    many = [Obj(f"o{i}", "candy", "red", (5 + i * 0.6, 240), (4, 4), score=0.5 + i / 4000) for i in range(1000)]
    out = run_in_process(
        __import__("testkit.scenarios", fromlist=["Scenario"]).Scenario(
            "many", by_time(scene(many, -1.0, 2.0, 0.5) + pointing(None) + [say(0.0, 1.5, "hello")]), []
        )
    )
    (cmd,) = out
    assert isinstance(cmd, FusedCommand) and "Objects in view (1000, 25 most confident listed)" in cmd.prompt
    assert len(cmd.prompt.splitlines()) < 40


def test_named_places_are_published_in_the_command():
    from testkit.scenarios import Scenario, run_in_process, say

    out = run_in_process(Scenario("place", [say(0.0, 1.2, "go to the kitchen")], []))
    (cmd,) = out
    assert cmd.intent == "go_to" and cmd.place == "kitchen" and cmd.location is None
    out = run_in_process(Scenario("no place", [say(0.0, 1.2, "come here")], []))
    assert out[0].place is None


def test_one_builder_for_commands_and_questions():
    from common.schema import Clarification, Location
    from services.fusion.decision import Act
    from services.fusion.ground import MAX_CANDIDATES
    from services.fusion.outputs import Outputs
    from testkit.scenarios import scene_of
    from testkit.scenarios.suite import CANDIES

    build = Outputs("fusion/test")
    t, _ = utterance(0.0, "put it there")
    ctx = window(scene_of(CANDIES))
    out = build.command(
        t, Act("put_down", confidence=1.7, explanation="why", location=Location(x=12.0, y=34.0, cam="cam0")), ctx
    )
    cmd = out.sample
    assert cmd.id == stable_id("cmd", t.source, t.stamp, t.mic) and cmd.confidence == 1.0 and not out.realtime
    assert cmd.location == Location(x=12.0, y=34.0, cam="cam0") and cmd.weights == ctx.weights
    assert "Location: pixel (12, 34) in camera cam0" in cmd.prompt and "Missing inputs: gesture" in cmd.prompt
    spoken_stop = build.command(t, Act("stop", confidence=0.8, explanation="stop", realtime=True), None)
    assert spoken_stop.realtime and spoken_stop.sample.weights.speech == 1.0
    assert spoken_stop.sample.inputs == {"speech": t.stamp, "vision": None, "gesture": None}
    question = build.clarification(t, "ambiguous", "Which one?", ctx.objects).sample
    assert isinstance(question, Clarification) and question.id == stable_id("clr", t.source, t.stamp, t.mic)
    assert len(ctx.objects) > MAX_CANDIDATES and len(question.candidates) == MAX_CANDIDATES


def test_the_prompts_most_confident_objects_are_those_sorting_all_would_list() -> None:
    """`most_confident` sorts only what scores at least the n-th best (issue #34): with many equal scores, across
    cameras, fewer objects than asked, it lists exactly what sorting every object would."""
    import dataclasses
    import random

    from services.fusion.describe import most_confident
    from testkit.scenarios import scene_of

    rng = random.Random(3)
    objs = [Obj(f"o{i:03d}", "cup", "red", (10.0, 10.0), score=rng.choice((0.3, 0.5, 0.5, 0.9))) for i in range(300)]
    objects = [dataclasses.replace(o, cam=rng.choice(("cam0", "cam1"))) for o in scene_of(objs)]
    for n in (1, 5, 25, 299, 300, 400):
        expected = sorted(objects, key=lambda o: (-o.score, o.cam, o.id))[:n]
        assert most_confident(objects, n) == expected
