"""Unit tests of fusion's outputs (services/fusion/outputs.py): ids, the planner prompt, what a command carries."""

from __future__ import annotations

from common.schema import FusedCommand
from services.fusion.outputs import stable_id
from tests.scenarios import Obj, by_time, pointing, run_in_process, say, scene


def test_ids_are_deterministic_and_distinct():
    assert stable_id("cmd", "speech/mic0", 1.5, "mic0") == stable_id("cmd", "speech/mic0", 1.5, "mic0")
    assert stable_id("cmd", "speech/mic0", 1.5, "mic0") != stable_id("cmd", "speech/mic0", 1.6, "mic0")


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
