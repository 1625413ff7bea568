"""Issue #43, the robot's profile (common/robot.py, docs/robot.md): the shipped profiles load, the default file is the
built-in default, a malformed profile is refused saying what is wrong and where, and fusion's affordances, refusals
and planner prompt follow the profile (in process, on the room of tests/test_fusion_afford.py and on the real indoor
scenes of ../shared/data/scenes/ for the five chair lines)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest

from common.language import COCO_LABELS, NOT_GRASPABLE
from common.robot import DEFAULT, TYPICAL_WEIGHT_KG, ProfileError, load_profile, parse_profile
from common.schema import Clarification, FusedCommand, RobotProfile, validate
from testkit.room3d import thing
from testkit.scenarios import Obj, Scenario, run_in_process, say, see

ROOT = Path(__file__).resolve().parent.parent
PROFILES = ROOT / "profiles"
TABLETOP = load_profile(PROFILES / "tabletop_arm.toml")
MOBILE = load_profile(PROFILES / "mobile_manipulator.toml")


def test_the_default_file_is_the_built_in_default():
    written = load_profile(PROFILES / "default.toml")
    assert dataclasses.replace(written, path=None) == DEFAULT
    assert DEFAULT.is_default and not written.is_default
    never = {label for labels in DEFAULT.never_grasp.values() for label in labels}
    assert never == NOT_GRASPABLE and DEFAULT.max_weight_kg is None  # today's fixed list, no weight limit


def test_every_coco_class_has_a_typical_weight():
    assert set(COCO_LABELS) <= set(TYPICAL_WEIGHT_KG)


@pytest.mark.parametrize("path", sorted(PROFILES.glob("*.toml")), ids=lambda p: p.name)
def test_every_shipped_profile_loads_and_goes_on_the_wire(path: Path):
    profile = load_profile(path)
    sample = validate(profile.sample(1_790_000_000.0, "fusion/test"))
    assert isinstance(sample, RobotProfile) and sample.name == profile.name
    assert profile.words().startswith(profile.name)


def test_the_example_profiles_say_what_each_robot_can_and_cannot_do():
    assert MOBILE.class_reason("chair") is None  # it lifts a stool or a chair (about 5 kg, under its 8 kg)
    assert MOBILE.class_reason("couch") == "it weighs about 40 kg, over my 8 kg"
    assert TABLETOP.class_reason("laptop") == "it weighs about 2 kg, over my 1 kg"
    assert TABLETOP.class_reason("chair") == "I don't lift furniture"
    assert TABLETOP.class_reason("cup") is None
    assert TABLETOP.missing_ability("go_to") == "I can't move from where I stand"
    assert TABLETOP.missing_ability("bring") == "I can't carry things to you"
    assert TABLETOP.missing_ability("pick_up") is None and MOBILE.missing_ability("follow") is None
    assert TABLETOP.weights_kg["bottle"] == 0.5 and TABLETOP.camera is not None


MALFORMED = [
    ('name = "x"\n[grasp]\nmax_weight_kg = "two"\n', "[grasp] max_weight_kg: expected a number, got 'two'"),
    ('name = "x"\n[grasp]\nmax_weight_kg = -1\n', "[grasp] max_weight_kg: expected a number > 0"),
    ('name = "x"\n[grasp.never]\nfurniture = ["chair", "sofa", "spaceship"]\n', "[grasp.never] furniture[2]"),
    ('name = "x"\n[abilities]\nflies = true\n', "[abilities]: unknown key(s) flies"),
    ('name = "x"\n[abilities]\nnavigates = "yes"\n', "[abilities] navigates: expected true or false"),
    ('name = "x"\n[busy]\nwhile_busy = "ignore"\n', "[busy] while_busy: expected one of ask, queue"),
    ('name = "x"\nmax_weight = 3\n', "top level: unknown key(s) max_weight"),
    ('name = "x"\n[camera]\nframe_id = "c"\nxyz = [0, 0]\nrpy = [0, 0, 0]\n', "[camera] xyz: expected 3 numbers"),
    ("[grasp]\nmax_size_m = 1\n", "name: expected a non-empty string"),
    ('name = "x"\n[grasp\n', "not valid TOML"),
]


@pytest.mark.parametrize("text,message", MALFORMED, ids=[m for _, m in MALFORMED])
def test_a_malformed_profile_says_what_is_wrong_and_where(text: str, message: str):
    with pytest.raises(ProfileError) as err:
        parse_profile(text, "bad.toml")
    assert str(err.value).startswith("robot profile bad.toml: ") and message in str(err.value), str(err.value)


def test_a_synonym_names_its_class_and_a_missing_file_is_an_error(tmp_path: Path):
    assert parse_profile('name = "x"\n[grasp.never]\nfurniture = ["sofa"]\n').never_grasp == {"furniture": ("couch",)}
    with pytest.raises(ProfileError, match="cannot read it"):
        load_profile(tmp_path / "missing.toml")


# -- fusion with a profile: affordances, refusals with the reason, the planner prompt ---------------------------------
TABLE = [Obj("cup_1", "cup", "red", (150, 300)), Obj("laptop_1", "laptop", "grey", (400, 300), (200, 120))]


def run(text: str, profile=None, objects=TABLE) -> FusedCommand | Clarification:
    steps = [see(t / 10, objects) for t in range(-10, 16, 2)] + [say(0.0, 1.2, text)]
    out = run_in_process(Scenario(text, sorted(steps, key=lambda s: s.t), []), profile=profile)
    assert len(out) == 1 and isinstance(out[0], (FusedCommand, Clarification)), out
    return out[0]


def test_a_tabletop_arm_refuses_a_laptop_by_its_weight_the_default_picks_it_up():
    assert isinstance(cmd := run("pick up the laptop"), FusedCommand) and cmd.target and cmd.target.id == "laptop_1"
    no = run("pick up the laptop", TABLETOP)
    assert isinstance(no, Clarification) and no.reason == "not_found" and no.candidates == []
    assert no.question == "I can't pick up a laptop: it weighs about 2 kg, over my 1 kg."
    cup = run("pick up the cup", TABLETOP)
    assert isinstance(cup, FusedCommand) and cup.target is not None and cup.target.id == "cup_1"


def test_a_robot_without_a_base_or_carrying_says_so():
    for text in ("go to the kitchen", "come here", "bring me the cup"):
        no = run(text, TABLETOP)
        assert isinstance(no, Clarification) and no.reason == "not_found", (text, no)
        assert no.question.startswith("I can't do that: I can't "), no.question
    assert isinstance(run("go to the kitchen"), FusedCommand)  # the default navigates


def test_the_planner_prompt_says_what_a_profiled_robot_can_do_and_the_default_adds_nothing():
    cmd = run("pick up the cup", TABLETOP)
    assert isinstance(cmd, FusedCommand)
    assert "\nRobot: tabletop-arm: grasps objects up to 1 kg, at most 0.3 m across" in cmd.prompt
    assert "cannot carry or navigate" in cmd.prompt
    default = run("pick up the cup")
    assert isinstance(default, FusedCommand) and "Robot" not in default.prompt


def test_a_stool_is_a_chair_and_the_mobile_manipulator_lifts_it():
    objects = [Obj("chair_1", "chair", "red", (300, 250), (160, 240)), Obj("cup_1", "cup", "blue", (100, 400))]
    no = run("pick up the big red stool", objects=objects)
    assert isinstance(no, Clarification) and no.question == "I can't pick up a chair: I don't lift furniture."
    yes = run("pick up the big red stool", MOBILE, objects=objects)
    assert isinstance(yes, FusedCommand) and yes.target is not None and yes.target.id == "chair_1", yes


def test_with_depth_the_size_limit_is_the_profiles():
    """A 0.45 m wide box: the default (0.6 m) picks it up, the tabletop arm (0.3 m) says it is too big."""
    from testkit.room3d import detections, step

    box = thing("box", "box", [0.0, 0.5, 1.5], size=(0.45, 0.3, 0.3))
    steps = [step(t / 10, lambda s: detections([box], s)) for t in range(-10, 16, 2)] + [
        say(0.0, 0.8, "pick up the box")
    ]
    scenario = Scenario("box", sorted(steps, key=lambda s: s.t), [])
    (ok,) = run_in_process(scenario)
    assert isinstance(ok, FusedCommand) and ok.target is not None
    (no,) = run_in_process(scenario, profile=TABLETOP)
    assert isinstance(no, Clarification) and no.question.startswith("I can't pick up the box: 0.45 m across"), no


# -- the five chair lines of the real indoor scenes (../shared/data/scenes/, the development set) ---------------------
CHAIR_VERBS = ("bring me", "pick up")


@pytest.fixture(scope="module")
def chair_lines():
    pytest.importorskip("onnxruntime")
    from testkit.scenarios.indoor import SCENES, load_lines, vision_pipeline
    from testkit.shared import shared_path, yolox_model

    folder = shared_path(SCENES)
    lines = [line for line in load_lines(folder) if "chair" in line.say or "stool" in line.say]
    see_photo = vision_pipeline(yolox_model())
    seen = {photo: see_photo(folder / photo) for photo in {line.photo for line in lines}}
    return lines, seen


def _as_commands(lines):
    """Each line said as a command to lift it ("the chair on the right" -> "bring me the chair on the right")."""
    from testkit.scenarios.indoor import Line

    for line in lines:
        verbs = [""] if line.say.startswith(CHAIR_VERBS) else [f"{v} " for v in CHAIR_VERBS]
        for verb in verbs:
            yield Line(line.photo, verb + line.say, line.expect, line.note)


def test_the_five_chair_lines_resolve_with_a_profile_that_lifts_chairs(chair_lines):
    from testkit.scenarios.indoor import judge, scenario

    lines, seen = chair_lines
    assert len(lines) == 5, [line.say for line in lines]
    for line in _as_commands(lines):
        ok, got = judge(line, run_in_process(scenario(line, seen[line.photo]), profile=MOBILE))
        assert ok, (line.say, got)


def test_the_five_chair_lines_are_refused_with_the_reason_by_default(chair_lines):
    from testkit.scenarios.indoor import scenario

    lines, seen = chair_lines
    for line in _as_commands(lines):
        out = run_in_process(scenario(line, seen[line.photo]))
        assert len(out) == 1 and isinstance(out[0], Clarification), (line.say, out)
        verb = "bring" if line.say.startswith("bring") else "pick up"
        assert out[0].question == f"I can't {verb} a chair: I don't lift furniture.", (line.say, out[0].question)
        assert out[0].reason == "not_found" and out[0].candidates == []


def test_a_wave_brings_a_robot_with_a_base_and_not_a_tabletop_arm():
    from services.fusion.gestures import WAVE_HOLD_S
    from testkit.scenarios import gesture

    steps = [see(t / 10, TABLE) for t in range(-10, 16, 2)] + [gesture(1.0, "wave", duration=WAVE_HOLD_S)]
    scenario = Scenario("wave", sorted(steps, key=lambda s: s.t), [])
    (come,) = run_in_process(scenario)
    assert isinstance(come, FusedCommand) and come.intent == "come_here"
    assert run_in_process(scenario, profile=TABLETOP) == []  # it cannot come: nothing is sent
