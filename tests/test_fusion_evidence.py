"""Unit tests of fusion's evidence (services/fusion/evidence.py): pointing selection and stability, image quality,
modality weights, speech reliability."""

from __future__ import annotations

from common.schema import ImageQuality
from services.fusion.evidence import image_quality, modality_weights, select_pointing, speech_reliability
from services.fusion.parse import parse
from testkit.fusion import pointing_obs
from testkit.scenarios import BASE_STAMP, DARK, GOOD, say


def test_pointing_steady_ray_is_stable_and_shaky_ray_is_not():
    steady = select_pointing([pointing_obs(1.0 + i * 0.1, (1, -1)) for i in range(6)], 1.2)
    shaky = select_pointing([pointing_obs(1.0 + i * 0.1, (1, -1 + (0.6 if i % 2 else -0.6))) for i in range(6)], 1.2)
    assert steady.stability > 0.95 and shaky.stability < 0.3
    assert steady.reliability > shaky.reliability


def test_pointing_nearest_to_the_deictic_word_wins():
    obs = [pointing_obs(0.0, (-1, -1)), pointing_obs(3.0, (1, -1))]
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
