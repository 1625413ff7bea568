"""Grounding by name on scenes made from the real YOLOX-Nano model's detections on real photos
(testkit/scenarios/real.py), in process. The same scenarios run over Zenoh in test_fusion_scenarios.py and are
scored in benchmarks/fusion_eval.py. Skipped with the reason when the model (../shared/) is absent."""

from __future__ import annotations

from pathlib import Path

import pytest

from common.schema import Clarification
from testkit.scenarios import check, describe, run_in_process
from testkit.scenarios.real import CASES, FRUIT_PHOTO, real_scenarios, yolox_detector
from testkit.shared import ROOT, shared_path, yolox_model


def photo(name: str) -> Path:
    return ROOT / name[5:] if name.startswith("repo:") else shared_path(name)


@pytest.fixture(scope="module")
def detect():
    pytest.importorskip("onnxruntime")
    return yolox_detector(yolox_model())


@pytest.fixture(scope="module")
def scenarios(detect):
    return real_scenarios(detect, photo)


@pytest.mark.parametrize("index", range(len(CASES)), ids=[f"{Path(c[0]).name}: {c[1]}" for c in CASES])
def test_real_scene(scenarios, index):
    sc = scenarios[index]
    outputs = run_in_process(sc)
    assert not check(sc, outputs), (check(sc, outputs), [describe(o) for o in outputs])


def test_the_fruit_question_names_fruit_only_and_the_banana_is_not_another_fruit(detect, scenarios):
    found, _, _ = detect(photo(FRUIT_PHOTO))
    labels = [label for label, _, _ in found]
    assert "banana" not in labels and len([x for x in labels if x in ("apple", "orange")]) >= 2, found
    fruit = next(s for s in scenarios if s.name.endswith("Bring me the fruit."))
    (question,) = run_in_process(fruit)
    assert isinstance(question, Clarification) and "fruit" in question.question, question.question
    assert "frisbee" not in question.question and {c.label for c in question.candidates} <= {"apple", "orange"}
