"""Building blocks for the fusion unit tests beside the scenarios: a pointing observation, even modality weights,
a join window over given objects, a parsed utterance."""

from __future__ import annotations

import math

from common.schema import Transcript, Weights
from services.fusion.evidence import PointingObs
from services.fusion.join import Ready
from services.fusion.parse import Utterance, parse
from services.fusion.window import Context
from testkit.scenarios import BASE_STAMP, say


def pointing_obs(t, direction, conf=0.9, cam="cam0") -> PointingObs:
    """A right hand at the bottom of a 640x480 image pointing along `direction` (normalised) at time `t`."""
    n = math.hypot(*direction)
    return PointingObs(t, cam, "right", (320.0, 470.0), (direction[0] / n, direction[1] / n), conf, 640, 480)


EVEN = Weights(speech=0.4, vision=0.2, gesture=0.4)


def window(objects, speech: float = 0.9) -> Context:
    """A ready join window over `objects` at BASE_STAMP: even weights, speech (reliability `speech`) and vision
    fresh, no gesture."""
    return Context(
        objects,
        [],
        None,
        EVEN,
        {"speech": speech, "vision": 0.9, "gesture": None},
        {"speech": BASE_STAMP, "vision": BASE_STAMP, "gesture": None},
        ["gesture"],
        BASE_STAMP,
        Ready("watermarks"),
        adaptive=True,
        margin=0.1,
    )


def utterance(start: float, text: str) -> tuple[Transcript, Utterance]:
    """(Transcript, parse) of `text` said from `start` for one second after BASE_STAMP."""
    _, t = say(start, start + 1.0, text).build(BASE_STAMP)
    assert isinstance(t, Transcript)
    return t, parse(t.text)
