"""The scenario suite against the real fusion process over Zenoh on loopback.

One router + one fusion process serve the whole suite: scenarios are separated in source time
(SCENARIO_SPACING s apart) and each ends with a sentinel utterance ("hello") whose command can
only come after every earlier utterance has been decided (fusion decides in utterance order).
"""

from __future__ import annotations

import time

import pytest

from common.schema import Clarification, FusedCommand
from testkit.harness import Client, ProcessGroup
from testkit.scenarios import (
    BASE_STAMP,
    SCENARIO_SPACING,
    Scenario,
    check,
    describe,
    gesture,
    hands,
    run_in_process,
    say,
    see,
)
from testkit.scenarios.suite import SCENARIOS

pytestmark = pytest.mark.integration

# s after the scenario base: after every scenario step, and within fusion's 30 s buffer horizon of them
# (samples on different keys may overtake each other on the way, so the sentinel's frames can be
# buffered before a scenario's transcript is; they must not push its window out of the buffers).
SENTINEL_AT = 25.0
SPEEDUP = 20.0


def _scenario_base(index: int) -> float:
    return BASE_STAMP + index * SCENARIO_SPACING


class FusionRig:
    """A router, a fusion process and a test client subscribed to fusion's outputs."""

    def __init__(self, *fusion_args: str):
        self.group = ProcessGroup()
        self.group.router()
        self.fusion = self.group.service("fusion", "--log-level", "INFO", *fusion_args)
        self.client = Client(self.group.endpoint)
        self.outputs = self.client.collect("hri/fusion/**")
        self.client.wait_alive("fusion")
        self.warm_up()

    def warm_up(self, timeout: float = 30.0) -> None:
        """Publish one harmless sample per input key until fusion receives all of them: the routes
        from this client to fusion's subscriptions exist before a scenario's first sample is sent."""
        deadline = time.monotonic() + timeout
        round_ = 0
        while time.monotonic() < deadline:
            before = self.client.stats("fusion")["received"]
            base = BASE_STAMP - 10_000 + round_
            for step in (
                see(0.0, []),
                hands(0.0),
                say(0.0, 0.5, "what", mic="warmup"),
                gesture(0.0, "fist", score=0.1),
            ):
                self.client.publish(*step.build(base))
            time.sleep(0.3)
            if self.client.stats("fusion")["received"] - before >= 4:
                return
            round_ += 1
        raise AssertionError(f"fusion never received the warm-up samples\n{self.group.logs()}")

    def run(self, scenario: Scenario, base: float, timeout: float = 30.0) -> list:
        # Paced at SPEEDUP x real time: fusion's subscriptions each have their own callback thread, so
        # samples on different keys sent within microseconds of each other may be handled in any order;
        # live services are milliseconds apart (a replay at 20x keeps that order with a wide margin).
        previous = None
        for step in scenario.steps:
            if previous is not None and step.t > previous:
                time.sleep((step.t - previous) / SPEEDUP)
            previous = step.t
            self.client.publish(*step.build(base))
        sentinel = [
            see(SENTINEL_AT + 1.0, []),
            hands(SENTINEL_AT + 1.0),
            say(SENTINEL_AT - 1.0, SENTINEL_AT, "hello", mic="sentinel", lag=0.0),
        ]
        for step in sentinel:
            self.client.publish(*step.build(base))
        sentinel_stamp = base + SENTINEL_AT
        try:
            self.outputs.wait(1, timeout, where=lambda k, s: isinstance(s, FusedCommand) and s.stamp == sentinel_stamp)
        except TimeoutError:
            raise AssertionError(f"no answer to the sentinel of {scenario.name!r}\n{self.group.logs()}") from None
        self.outputs.drain(0.05)
        return [
            s
            for _, s in self.outputs.seen
            if isinstance(s, (FusedCommand, Clarification)) and base - 10 <= s.stamp < base + SENTINEL_AT
        ]

    def close(self) -> None:
        self.client.close()
        self.group.close()


@pytest.fixture(scope="module")
def rig():
    r = FusionRig()
    try:
        yield r
    finally:
        r.close()


DEFAULT_SCENARIOS = [(i, s) for i, s in enumerate(SCENARIOS) if not s.config]


def test_the_suite_has_enough_scenarios():
    assert len(SCENARIOS) >= 40
    tags = {t for s in SCENARIOS for t in s.tags}
    for needed in (
        "colour",
        "class",
        "position",
        "pointing",
        "conflict",
        "dialogue",
        "missing",
        "order",
        "gesture",
        "timing",
    ):
        assert needed in tags, f"no scenario tagged {needed!r}"


@pytest.mark.parametrize("index,scenario", DEFAULT_SCENARIOS, ids=[s.name for _, s in DEFAULT_SCENARIOS])
def test_scenario_over_zenoh(rig, index, scenario):
    base = _scenario_base(index)
    outputs = rig.run(scenario, base)
    problem = check(scenario, outputs)
    assert not problem, f"{scenario.name}: {problem}"
    # The process decides exactly as the core does in process: same ids, same outcomes.
    in_process = run_in_process(scenario, base=base)
    assert [(o.id, type(o).__name__) for o in outputs] == [(o.id, type(o).__name__) for o in in_process], [
        describe(o) for o in in_process
    ]


def test_outputs_carry_weights_explanation_and_prompt(rig):
    scenario = next(s for s in SCENARIOS if s.name == "pointing: that cup")
    outputs = rig.run(scenario, _scenario_base(len(SCENARIOS) + 1))
    (cmd,) = outputs
    assert abs(cmd.weights.speech + cmd.weights.vision + cmd.weights.gesture - 1.0) < 1e-3
    assert cmd.weights.gesture > 0 and cmd.gesture == "point"
    assert set(cmd.inputs) == {"speech", "vision", "gesture"} and all(v is not None for v in cmd.inputs.values())
    assert "cup_blue" in cmd.explanation and "pointing ray" in cmd.explanation
    for needed in ("Command: pick_up", "Target: cup_blue", "cup_red", "Gesture:", "Objects in view (2)"):
        assert needed in cmd.prompt, f"{needed!r} missing from the prompt:\n{cmd.prompt}"


def test_invalid_samples_are_counted_and_the_service_goes_on(rig):
    rig.client.put_raw("hri/speech/mic0/transcript", b"\x93not a transcript")
    rig.client.put_raw("hri/vision/cam0/objects", b"\xc1")
    scenario = next(s for s in SCENARIOS if s.name == "speech: hello")
    outputs = rig.run(scenario, _scenario_base(len(SCENARIOS) + 2))
    assert [o.intent for o in outputs] == ["greet"]
    stats = rig.client.stats("fusion")
    assert sum(stats["rejected"].values()) >= 2, stats


def test_fallback_to_the_most_confident_detection_is_an_option():
    scenario = next(s for s in SCENARIOS if s.config.get("fallback_most_confident"))
    default_rig = None
    try:
        default_rig = FusionRig("--fallback-most-confident")
        outputs = default_rig.run(scenario, _scenario_base(0))
        assert not check(scenario, outputs), check(scenario, outputs)
    finally:
        if default_rig is not None:
            default_rig.close()


def test_replay_into_a_fresh_process_reproduces_the_commands(rig):
    """The same samples into a second, fresh fusion process give the same ids, intents, targets and prompts."""
    chosen = [
        s
        for s in SCENARIOS
        if s.name
        in (
            "pointing: that cup",
            "follow-up: the red one",
            "conflict: says red, points blue",
            "go there: a location",
            "out of order: shuffled inputs",
        )
    ]
    base0 = _scenario_base(len(SCENARIOS) + 10)
    first = [rig.run(s, base0 + i * SCENARIO_SPACING) for i, s in enumerate(chosen)]
    fresh = FusionRig()
    try:
        second = [fresh.run(s, base0 + i * SCENARIO_SPACING) for i, s in enumerate(chosen)]
    finally:
        fresh.close()

    def summary(outs):
        return [
            (
                o.id,
                type(o).__name__,
                getattr(o, "intent", None),
                getattr(getattr(o, "target", None), "id", None),
                getattr(o, "location", None),
                getattr(o, "reason", None),
                getattr(o, "prompt", None),
            )
            for o in outs
        ]

    assert [summary(o) for o in first] == [summary(o) for o in second]


def test_fusion_stops_cleanly_on_sigterm():
    r = FusionRig()
    try:
        code, took = r.fusion.terminate(timeout=3.0)
        assert code == 0, r.fusion.output()
        assert took < 2.5
    finally:
        r.close()


def test_real_photo_scenes_over_zenoh(rig):
    """Scenes from the real YOLOX-Nano detections on real photos (testkit/scenarios/real.py), published to the
    real process: the same outcomes as in process. Skipped without ../shared/."""
    pytest.importorskip("onnxruntime")
    from testkit.scenarios.real import real_scenarios, yolox_detector
    from testkit.shared import ROOT, shared_path, yolox_model

    scenarios = real_scenarios(
        yolox_detector(yolox_model()), lambda name: ROOT / name[5:] if name.startswith("repo:") else shared_path(name)
    )
    problems = []
    for i, sc in enumerate(scenarios):
        base = _scenario_base(len(SCENARIOS) + 30 + i)
        outputs = rig.run(sc, base)
        problem = check(sc, outputs)
        in_process = run_in_process(sc, base=base)
        if problem or [o.id for o in outputs] != [o.id for o in in_process]:
            problems.append(f"{sc.name}: {problem or 'differs from in process'} {[describe(o) for o in outputs]}")
    assert not problems, problems
