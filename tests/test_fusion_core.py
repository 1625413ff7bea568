"""Unit tests of fusion's decisions (services/fusion/core.py, no zenoh): every scenario in process, independence
from delivery order, never the wrong object by default, flat memory."""

from __future__ import annotations

import random

import pytest

from common.schema import Clarification
from services.fusion.core import Config, FusionCore
from testkit.scenarios import BASE_STAMP, check, pointing, run_in_process, say, scene
from testkit.scenarios.suite import BLUE_CUP, SCENARIOS, TWO_CUPS, normal


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
        seq[: len(early)] = early
    order, queues = [], [list(q) for q in per_key.values()]
    while any(queues):
        q = rng.choice([q for q in queues if q])
        order.append(q.pop(0))
    return order


@pytest.mark.parametrize(
    "name",
    [
        "pointing: that cup",
        "follow-up: pointing and that one",
        "conflict: says red, points blue",
        "late gesture within the window",
        "candies: the blue one on the left",
        "stop gesture during speech wins",
        "out of order: shuffled inputs",
    ],
)
def test_decisions_do_not_depend_on_delivery_order(name):
    scenario = next(s for s in SCENARIOS if s.name == name)
    reference = run_in_process(scenario)
    assert not check(scenario, reference)
    for seed in range(6):
        shuffled = run_in_process(scenario, order=interleaved(scenario, seed))
        assert [o.to_dict() for o in shuffled] == [o.to_dict() for o in reference], seed


def test_every_scenario_in_process():
    failures = {s.name: check(s, run_in_process(s)) for s in SCENARIOS}
    assert not {k: v for k, v in failures.items() if v}


def test_wrong_object_is_never_chosen_by_default_when_nothing_fits():
    scenario_steps = normal(TWO_CUPS, "pick up the green ball")
    from testkit.scenarios import Scenario

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


def test_the_service_pauses_the_collector_only_until_a_decisions_output_is_out() -> None:
    """`collector_after_output` (services/fusion/__main__.py, issue #34): the collector is paused inside, running again
    after, also when the decision raised; a collector the process had turned off stays off."""
    import gc

    from services.fusion.__main__ import collector_after_output

    assert gc.isenabled()
    with collector_after_output():
        assert not gc.isenabled()
    assert gc.isenabled()
    with pytest.raises(ValueError):
        with collector_after_output():
            raise ValueError("a failed decision")
    assert gc.isenabled()
    gc.disable()
    try:
        with collector_after_output():
            pass
        assert not gc.isenabled()
    finally:
        gc.enable()
