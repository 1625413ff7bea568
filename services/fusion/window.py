"""One transcript's window: the utterance waiting for its inputs (`PendingTranscript`), and what the buffers hold
for it once it closes (`Context`: the objects in view, the pointing, the modality weights), gathered by `gather`."""

from __future__ import annotations

import logging
from dataclasses import dataclass

from common.language import DEICTIC_OBJECT_WORDS, DEICTIC_PLACE_WORDS
from common.schema import GESTURE, SPEECH, VISION, Detections, Hands, Modality, Transcript, Weights
from services.fusion.evidence import (
    Pointing,
    modality_weights,
    pointing_from_event,
    pointing_from_hands,
    select_pointing,
    speech_reliability,
    vision_reliability,
)
from services.fusion.ground import Choice, SceneObject, Scored, choose, scene_objects, shortlist
from services.fusion.join import WAITED_MODALITIES, Ready, Streams
from services.fusion.parse import ObjectPhrase, Utterance, word_key
from services.fusion.people import competing, speakers_items


@dataclass
class PendingTranscript:
    key: str
    transcript: Transcript
    utterance: Utterance
    arrived: float  # wall
    lo: float
    hi: float

    @property
    def order(self) -> tuple[float, float, str]:
        """Decided in the order spoken: the dialogue sees utterances as the person said them."""
        return self.transcript.end, self.transcript.stamp, self.transcript.source


@dataclass
class Context:
    """What the window holds for one transcript, and the rules it is weighed by."""

    objects: list[SceneObject]
    detections: list[Detections]
    pointing: Pointing | None
    weights: Weights
    reliabilities: dict[Modality, float | None]
    inputs: dict[str, float | None]
    missing: list[str]
    ref: float
    how: Ready  # why the window was closed
    adaptive: bool  # --weights adaptive
    margin: float  # the lead a winner needs
    competing: tuple[Pointing, ...] = ()  # speaker unknown, several people point: each one's (fusion/people.py)
    # What the command may act on (services/fusion/afford.py): None = every object in view. `objects` stays the
    # whole scene (a relation's anchor, the prompt's objects in view).
    candidates: list[SceneObject] | None = None

    @property
    def pool(self) -> list[SceneObject]:
        """The objects the command may act on."""
        return self.objects if self.candidates is None else self.candidates

    def choose(
        self,
        phrase: ObjectPhrase,
        objects: list[SceneObject],
        pointing: Pointing | None,
        ref: float | None,
        check_evidence: bool = True,
    ) -> Choice:
        """Score `objects` against the words (and `pointing`) with this window's weights, and decide. With the
        window's pointing and several people pointing (speaker unknown), each one's is grounded: when they pick
        different objects, which one is a question (`ambiguous` between them)."""
        if pointing is not None and pointing is self.pointing and self.competing:
            picks: dict[tuple[str, str], Scored] = {}
            for theirs in self.competing:
                choice = self.choose(phrase, objects, theirs, ref, check_evidence)
                if choice.kind == "target" and choice.winner is not None:
                    picks.setdefault(choice.winner.obj.key, choice.winner)
            if len(picks) > 1:
                return Choice("ambiguous", None, tuple(picks.values()))
        # what `choose` reads of the ranking (`shortlist`): the same decision as on the whole, 1000 objects fast
        scored = shortlist(phrase, objects, pointing, self.weights, adaptive=self.adaptive, ref=ref, scene=self.objects)
        return choose(phrase, scored, margin=self.margin, check_evidence=check_evidence)


def ref_time(t: Transcript, u: Utterance) -> float:
    """When the person meant the object: the deictic word if there is one, else mid-utterance."""
    if u.deictic:
        words = DEICTIC_OBJECT_WORDS + DEICTIC_PLACE_WORDS
        for w in t.words:
            if word_key(w.word) in words:
                offset = t.start if w.start < 1e6 <= t.start else 0.0  # relative word times
                return offset + (w.start + w.end) / 2
    return (t.start + t.end) / 2


def gather(
    streams: Streams,
    p: PendingTranscript,
    how: Ready,
    *,
    weights_mode: str,
    vision_lookback: float,
    margin: float,
    log: logging.Logger,
    speaker_person: str | None = None,
) -> Context:
    """The window's evidence: per camera the detections nearest the reference time (looking back
    `vision_lookback` before the window), the pointing nearest it, each modality's reliability and weight.
    `speaker_person`: who said it (None = unknown): another person's hands are no evidence for it."""
    t, u = p.transcript, p.utterance
    ref = ref_time(t, u)
    detections = []
    by_key: dict[str, list[Detections]] = {}
    for key, det in streams.between(VISION, p.lo - vision_lookback, p.hi):
        by_key.setdefault(key, []).append(det)
    for key in sorted(by_key):
        detections.append(min(by_key[key], key=lambda d: (abs(d.stamp - ref), d.stamp)))
    obs = []
    for _, item in speakers_items(streams.between(GESTURE, p.lo, p.hi), speaker_person):
        obs.extend(pointing_from_hands(item) if isinstance(item, Hands) else pointing_from_event(item))
    pointing = select_pointing(obs, ref)
    rel: dict[Modality, float | None] = {
        SPEECH: speech_reliability(t, u),
        VISION: vision_reliability(detections) if detections else None,
        GESTURE: pointing.reliability if pointing else None,
    }
    weights = modality_weights(weights_mode, rel)
    inputs = {
        SPEECH: t.stamp,
        VISION: max((d.stamp for d in detections), default=None),
        GESTURE: pointing.stamp if pointing else None,
    }
    missing = [m for m in WAITED_MODALITIES if inputs[m] is None]
    if log.isEnabledFor(logging.DEBUG):
        log.debug(
            "window [%.3f, %.3f] of '%s' closed by %s: %d detections, %d pointing observations, watermarks %s",
            p.lo,
            p.hi,
            t.text,
            how,
            len(detections),
            len(obs),
            {m: round(streams.watermark(m), 3) for m in WAITED_MODALITIES},
        )
    return Context(
        scene_objects(detections),
        detections,
        pointing,
        weights,
        rel,
        inputs,
        missing,
        ref,
        how,
        adaptive=weights_mode == "adaptive",
        margin=margin,
        competing=competing(obs, ref) if speaker_person is None else (),
    )
