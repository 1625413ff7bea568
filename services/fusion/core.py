"""The fusion core: buffers, the windowed join, decisions and the clarification dialogue.

A plain object driven by the service's single worker thread (no locks, no zenoh): feed it
samples with `on_*`, call `tick(wall)` regularly, publish what they return. Every decision is a
function of the samples' source stamps; wall time only decides *when* a window is closed (the
`max_wait` deadline) and which modalities are live.
"""

from __future__ import annotations

import collections
import hashlib
import logging
from dataclasses import dataclass, field, replace
from typing import Callable

from common.language import ANY_OBJECT, DEICTIC_OBJECT_WORDS, DEICTIC_PLACE_WORDS, label_matches
from common.schema import (
    Clarification, Detections, FusedCommand, GestureEvent, Hands, Location, Motion as WireMotion, Sample, Transcript,
    Weights,
)
from services.fusion import describe
from services.fusion.evidence import (
    Pointing, modality_weights, pointing_from_event, pointing_from_hands, select_pointing, speech_reliability,
    vision_reliability,
)
from services.fusion.ground import (
    DEFAULT_MARGIN, MAX_CANDIDATES, Choice, SceneObject, Scored, choose, ray_point, scene_objects, score,
)
from services.fusion.join import Liveness, Streams, WAITED_MODALITIES, ready
from services.fusion.parse import Motion, ObjectPhrase, Utterance, parse, word_key

TARGET_INTENTS = ("pick_up", "bring")  # must name an object
ON_RAY = 0.7  # gesture score from which "there" means the object on the ray
OPEN_PALM_FRAMES = 3  # hand frames showing an open palm during an utterance cancel it (one frame may be noise)


@dataclass
class Config:
    window_before: float = 1.0  # s of source time before the utterance start
    window_after: float = 0.3  # s after its end (a point that comes just after the word)
    max_wait: float = 0.5  # s of wall time after a transcript arrives: decide with what is there
    weights: str = "adaptive"  # or "fixed"
    fallback_most_confident: bool = False
    dialogue_timeout: float = 10.0  # s of source time a clarification stays open
    live_recent_s: float = 2.0  # a modality with samples this recent (wall) is live without a token
    horizon: float = 30.0  # s of source time kept per stream
    vision_lookback: float = 2.0  # detections this much older than the window still describe the scene
    margin: float = DEFAULT_MARGIN
    low_speech_confidence: float = 0.3  # below: confirm before acting (unless pointing carries it)
    gesture_min_score: float = 0.5  # open_palm / wave events below this are ignored
    episode_gap: float = 1.5  # s: events of one gesture this close belong to one episode (one command)


@dataclass
class Output:
    sample: Sample
    realtime: bool = False


@dataclass
class PendingTranscript:
    key: str
    transcript: Transcript
    utterance: Utterance
    arrived: float  # wall
    lo: float
    hi: float


@dataclass
class Draft:
    """A command that is ready except for the person's answer."""
    intent: str
    text: str
    target: SceneObject | None = None
    location: tuple[float, float, str] | None = None
    place: str | None = None
    motion: Motion | None = None


@dataclass
class LastCommand:
    """The latest command that acted on an object: "no, the other one" corrects it."""
    intent: str
    text: str
    target: SceneObject
    phrase: ObjectPhrase
    place: str | None
    expires: float  # source time


@dataclass
class Dialogue:
    clarification_id: str
    reason: str
    draft: Draft
    phrase: ObjectPhrase
    candidates: list[SceneObject]
    expires: float  # source time
    question: str


@dataclass
class Context:
    """What the window holds for one transcript."""
    objects: list[SceneObject]
    detections: list[Detections]
    pointing: Pointing | None
    weights: Weights
    reliabilities: dict[str, float | None]
    inputs: dict[str, float | None]
    missing: list[str]
    ref: float
    how: str  # why the window was closed (watermarks / deadline)


def stable_id(prefix: str, *parts: object) -> str:
    """Same inputs, same id: replaying a session reproduces the ids."""
    digest = hashlib.sha1("|".join(repr(p) for p in parts).encode()).hexdigest()
    return f"{prefix}-{digest[:16]}"


def modality_of(service: str) -> str | None:
    return {"speech": "speech", "vision": "vision", "gesture": "gesture"}.get(service)


class FusionCore:
    def __init__(self, config: Config, source: str, count: Callable[[str], None] = lambda name: None,
                 log: logging.Logger | None = None):
        self.cfg = config
        self.source = source
        self.count = count
        self.log = log or logging.getLogger("hri.fusion.core")
        self.streams = Streams(config.horizon)
        self.liveness = Liveness(config.live_recent_s)
        self.pending: list[PendingTranscript] = []
        self.dialogue: Dialogue | None = None
        self.last: LastCommand | None = None
        self.seen_transcripts: collections.OrderedDict[tuple[str, float], float] = collections.OrderedDict()
        self.gesture_stops: collections.deque[float] = collections.deque(maxlen=64)
        self.gesture_waves: collections.deque[float] = collections.deque(maxlen=64)
        self.episodes: dict[tuple, tuple[float, bool]] = {}  # (key, hand, gesture) -> (last stamp, ended)

    # -- inputs ---------------------------------------------------------------
    def _add(self, modality: str, key: str, stamp: float, item: object, wall: float, ident: object = None) -> bool:
        self.liveness.arrived(modality, wall)
        keep_from = min((q.lo for q in self.pending), default=None)
        if keep_from is not None:
            keep_from -= self.cfg.vision_lookback
        status = self.streams.add(modality, key, stamp, item, ident, keep_from)
        if status == "duplicate":
            self.count("duplicate")
            return False
        if status == "late":
            self.count("late")
            return False
        if status == "reset":
            self.count("timeline_reset")
            self.log.info("%s went back in time (consistent samples older than the %.0f s horizon: a replay "
                          "restarted or a clock stepped back): buffer for %s restarted", key, self.cfg.horizon,
                          modality)
        return True

    def on_detections(self, key: str, det: Detections, wall: float) -> list[Output]:
        self._add("vision", key, det.stamp, det, wall)
        return []

    def on_hands(self, key: str, hands: Hands, wall: float) -> list[Output]:
        self._add("gesture", key, hands.stamp, hands, wall)
        return []

    def on_gesture_event(self, key: str, ev: GestureEvent, wall: float) -> list[Output]:
        if not self._add("gesture", key, ev.stamp, ev, wall, ident=(ev.gesture, ev.phase, ev.hand)):
            return []
        if ev.gesture not in ("open_palm", "wave") or ev.score < self.cfg.gesture_min_score:
            return []
        episode = (key, ev.hand, ev.gesture)
        last = self.episodes.get(episode)
        new = last is None or last[1] or ev.start > last[0] + self.cfg.episode_gap or ev.stamp < last[0] - \
            self.cfg.horizon
        self.episodes[episode] = (max(ev.stamp, ev.end, last[0] if last and not new else 0.0), ev.phase == "end")
        self._prune_episodes(ev.stamp)
        if not new:
            return []
        if ev.gesture == "open_palm":
            self.gesture_stops.append(ev.start)
            self.dialogue = None
            return [self._gesture_command(ev, "stop", realtime=True,
                                          why=f"open palm shown by the {ev.hand} hand (score {ev.score:.2f}): "
                                              f"stop at once")]
        self.gesture_waves.append(ev.start)
        return [self._gesture_command(ev, "come_here", realtime=False,
                                      why=f"{ev.hand} hand waving (score {ev.score:.2f}): come here")]

    def _prune_episodes(self, stamp: float) -> None:
        if len(self.episodes) > 64:
            for k in [k for k, (s, _) in self.episodes.items() if s < stamp - self.cfg.horizon]:
                del self.episodes[k]

    def on_transcript(self, key: str, t: Transcript, wall: float) -> list[Output]:
        self.liveness.arrived("speech", wall)
        if not t.final:
            self.count("partial_ignored")
            return []
        ident = (t.source, t.stamp)
        if ident in self.seen_transcripts:
            self.count("duplicate")
            return []
        self.seen_transcripts[ident] = t.stamp
        while self.seen_transcripts and (len(self.seen_transcripts) > 1024 or next(
                iter(self.seen_transcripts.values())) < t.stamp - self.cfg.horizon):
            self.seen_transcripts.popitem(last=False)
        u = parse(t.text)
        if u.intent == "stop":  # no window to wait for: stop now
            self.dialogue = None
            weights = Weights(speech=1.0, vision=0.0, gesture=0.0)
            inputs = {"speech": t.stamp, "vision": None, "gesture": None}
            why = f"'{t.text}' asks to stop (speech confidence {t.confidence:.2f}); stopping never waits"
            cmd = self._command(t, "stop", weights=weights, inputs=inputs, confidence=t.confidence, explanation=why,
                                prompt=describe.planner_prompt(text=t.text, intent="stop", target=None, location=None,
                                                               place=None, pointing=None, gesture=None, objects=[],
                                                               missing=[], explanation=why))
            return [Output(cmd, realtime=True)]
        p = PendingTranscript(key, t, u, wall, t.start - self.cfg.window_before, t.end + self.cfg.window_after)
        self.pending.append(p)
        self.pending.sort(key=lambda q: (q.transcript.end, q.transcript.stamp, q.transcript.source))
        return []

    def on_liveliness(self, service: str, instance: str, present: bool) -> None:
        modality = modality_of(service)
        if modality:
            self.liveness.token(modality, instance, present)

    # -- the join -------------------------------------------------------------
    def tick(self, wall: float) -> list[Output]:
        out: list[Output] = []
        live = [m for m in WAITED_MODALITIES if self.liveness.live(m, wall)]
        marks = {m: self.streams.watermark(m) for m in WAITED_MODALITIES}
        while self.pending:
            head = self.pending[0]  # in stamp order: the dialogue sees utterances in the order spoken
            go, how = ready(head.hi, head.arrived, wall, self.cfg.max_wait, marks, live)
            if not go:
                break
            self.pending.pop(0)
            out.extend(self.decide(head, how))
        return out

    def _stop_shown(self, lo: float, hi: float) -> bool:
        """An open palm during the utterance: from a stop event, or from hand frames (which arrive in order
        with the gesture watermark, so the answer does not depend on whether the event overtook the transcript)."""
        if any(lo <= s <= hi for s in self.gesture_stops):
            return True
        frames = 0
        for _, item in self.streams.between("gesture", lo, hi):
            if isinstance(item, Hands) and any(h.gesture == "open_palm" and h.score >= self.cfg.gesture_min_score
                                               for h in item.hands):
                frames += 1
        return frames >= OPEN_PALM_FRAMES

    def _ref_time(self, t: Transcript, u: Utterance) -> float:
        """When the person meant the object: the deictic word if there is one, else mid-utterance."""
        if u.deictic:
            words = DEICTIC_OBJECT_WORDS + DEICTIC_PLACE_WORDS
            for w in t.words:
                if word_key(w.word) in words:
                    offset = t.start if w.start < 1e6 <= t.start else 0.0  # relative word times
                    return offset + (w.start + w.end) / 2
        return (t.start + t.end) / 2

    def context(self, p: PendingTranscript, how: str) -> Context:
        t, u = p.transcript, p.utterance
        ref = self._ref_time(t, u)
        detections = []
        by_key: dict[str, list[Detections]] = {}
        for key, det in self.streams.between("vision", p.lo - self.cfg.vision_lookback, p.hi):
            by_key.setdefault(key, []).append(det)
        for key in sorted(by_key):
            detections.append(min(by_key[key], key=lambda d: (abs(d.stamp - ref), d.stamp)))
        obs = []
        for _, item in self.streams.between("gesture", p.lo, p.hi):
            obs.extend(pointing_from_hands(item) if isinstance(item, Hands) else pointing_from_event(item))
        pointing = select_pointing(obs, ref)
        rel = {"speech": speech_reliability(t, u),
               "vision": vision_reliability(detections) if detections else None,
               "gesture": pointing.reliability if pointing else None}
        weights = modality_weights(self.cfg.weights, rel)
        inputs = {"speech": t.stamp, "vision": max((d.stamp for d in detections), default=None),
                  "gesture": pointing.stamp if pointing else None}
        missing = [m for m in WAITED_MODALITIES if inputs[m] is None]
        if self.log.isEnabledFor(logging.DEBUG):
            self.log.debug("window [%.3f, %.3f] of '%s' closed by %s: %d detections, %d pointing observations, "
                           "watermarks %s", p.lo, p.hi, t.text, how, len(detections), len(obs),
                           {m: round(self.streams.watermark(m), 3) for m in WAITED_MODALITIES})
        return Context(scene_objects(detections), detections, pointing, weights, rel, inputs, missing, ref, how)

    # -- decisions ------------------------------------------------------------
    def decide(self, p: PendingTranscript, how: str) -> list[Output]:
        t, u = p.transcript, p.utterance
        if self._stop_shown(t.start, p.hi):
            self.count("cancelled_by_stop_gesture")
            self.log.info("'%s' dropped: an open palm (stop) was shown while it was said", t.text)
            return []
        ctx = self.context(p, how)
        if u.unknown and ctx.objects:  # a user's own label in view ("the widget") is a noun too
            u = parse(t.text, labels=tuple(sorted({o.label for o in ctx.objects})))
        if self.dialogue is not None and t.start > self.dialogue.expires:
            self.count("dialogue_expired")
            self.dialogue = None
        if self.last is not None and t.start > self.last.expires:
            self.last = None
        if u.intent is None:
            if self.dialogue is not None and (u.has_content or ctx.pointing is not None):
                return self.answer(t, u, ctx)
            if self.last is not None and (u.other or (u.answer == "deny" and u.obj.specific)):
                return self.correct_last(t, u, ctx)
            self.count("ignored_no_intent")
            self.log.info("'%s' is not a command I know; ignored", t.text)
            return []
        self.dialogue = None  # a new command supersedes an open question
        self.last = None
        if u.intent == "come_here" and any(p.lo <= s <= p.hi for s in self.gesture_waves):
            self.count("duplicate_of_gesture")
            return []
        return self.command_for(t, u, ctx)

    def command_for(self, t: Transcript, u: Utterance, ctx: Context) -> list[Output]:
        intent = u.intent
        assert intent is not None
        speech_rel = ctx.reliabilities["speech"] or 0.0
        named = u.obj.specific or u.obj.noun is not None
        wants_object = intent in TARGET_INTENTS or (intent in ("look_at", "follow") and (
            named or u.obj.deictic)) or (intent == "go_to" and named)
        wants_location = (intent == "go_to" and not wants_object and not u.place) or (
            intent in ("put_down", "look_at") and not wants_object and (u.deictic_place or u.dest_obj))
        target: Scored | None = None
        runner_up: Scored | None = None
        overruled = None
        if wants_object and u.obj.noun is not None:  # a word I don't know: only a clear point can say which
            choice = self._choose(replace(u.obj, noun=None, color=None, label=None, spatial=(), deictic=True), ctx)
            if not (choice.kind == "target" and choice.winner is not None and (choice.winner.gesture or 0.0) >= 0.5):
                self.count("unknown_noun")
                return [self._clarify(t, u, ctx, Choice("not_found", None, ()), Draft(intent, t.text, place=u.place))]
            target, runner_up = choice.winner, choice.runner_up
        elif wants_object:
            choice = self._choose(u.obj, ctx)
            if choice.kind == "not_found" and self.cfg.fallback_most_confident and ctx.objects:
                best = max(ctx.objects, key=lambda o: (o.score, o.cam, o.id))
                scored = score(ObjectPhrase(), [best], None, ctx.weights, adaptive=False)[0]
                expl = (f"nothing fits '{u.obj.describe()}'; --fallback-most-confident picked the most confident "
                        f"detection {best.id} ({best.name()}, score {best.score:.2f})")
                return [self._target_command(t, intent, scored, None, ctx, expl, place=u.place)]
            if choice.kind not in ("target", "low_confidence"):
                return [self._clarify(t, u, ctx, choice, Draft(intent, t.text, place=u.place))]
            target = choice.winner
            runner_up = choice.runner_up
            overruled = choice.overruled
            if choice.kind == "low_confidence":
                return [self._clarify(t, u, ctx, choice, Draft(intent, t.text, target=target.obj, place=u.place))]
        elif intent == "put_down" and u.obj.specific:
            choice = self._choose(u.obj, ctx)  # the object may well be in the gripper, out of view: optional
            target = choice.winner if choice.kind == "target" else None
        location = None
        if wants_location:
            location = self._location(u, ctx)
            if location is None:
                return [self._clarify_place(t, u, ctx, Draft(intent, t.text, target=target.obj if target else None))]
        gesture_carried = target is not None and (target.gesture or 0.0) >= 0.5 and \
            ctx.weights.gesture >= ctx.weights.speech
        if speech_rel < self.cfg.low_speech_confidence and not gesture_carried:
            draft = Draft(intent, t.text, target=target.obj if target else None, location=location, place=u.place,
                          motion=u.motion)
            choice = Choice("low_confidence", target, (target,) if target else ())
            return [self._clarify(t, u, ctx, choice, draft, heard=True)]
        if target is not None:
            expl = describe.explain_target(target, runner_up, ctx.weights.to_dict(), u.obj, overruled)
            if u.obj.noun is not None:
                expl += f" ('{u.obj.noun}' is not a word I know; the pointing decided)"
            self.last = LastCommand(intent, t.text, target.obj, u.obj, u.place, t.end + self.cfg.dialogue_timeout)
            return [self._target_command(t, intent, target, location, ctx, expl, place=u.place)]
        expl = f"'{t.text}' -> {intent}" + (f" to the {u.place}" if u.place else "") + (
            f"; location from the pointing ray at ({location[0]:.0f}, {location[1]:.0f})" if location else "") + (
            f": {describe.motion_words(u.motion)}" if u.motion else "")
        return [Output(self._command(t, intent, weights=ctx.weights, inputs=ctx.inputs, location=location,
                                     confidence=speech_rel, explanation=expl,
                                     gesture="point" if location and ctx.pointing else None, place=u.place,
                                     motion=u.motion,
                                     prompt=self._prompt(t.text, intent, None, location, u.place, ctx, expl,
                                                         motion=u.motion)))]

    def _scored(self, phrase: ObjectPhrase, ctx: Context) -> list[Scored]:
        return score(phrase, ctx.objects, ctx.pointing, ctx.weights, adaptive=self.cfg.weights == "adaptive",
                     ref=ctx.ref)

    def _choose(self, phrase: ObjectPhrase, ctx: Context) -> Choice:
        return choose(phrase, self._scored(phrase, ctx), margin=self.cfg.margin)

    def _location(self, u: Utterance, ctx: Context) -> tuple[float, float, str] | None:
        if u.dest_obj is not None:  # "put it on the red box": the box is the place
            choice = self._choose(u.dest_obj, ctx)
            if choice.kind == "target" and choice.winner is not None:
                o = choice.winner.obj
                return (o.center[0], o.center[1], o.cam)
        p = ctx.pointing
        if p is None:
            return None
        on_ray = [o for o in ctx.objects if o.cam == p.cam]
        if on_ray:
            best = score(ObjectPhrase(), on_ray, p, Weights(speech=0.0, vision=0.0, gesture=1.0))[0]
            if (best.gesture or 0.0) >= ON_RAY:
                return (best.obj.center[0], best.obj.center[1], p.cam)
        x, y = ray_point(p)
        return (x, y, p.cam)

    # -- the dialogue ---------------------------------------------------------
    def answer(self, t: Transcript, u: Utterance, ctx: Context) -> list[Output]:
        d = self.dialogue
        assert d is not None
        if u.other:
            return self._other_answer(t, u, ctx, d)
        pointing_answer = u.obj.deictic or (ctx.pointing is not None and not u.obj.specific)
        if u.answer == "deny" and not u.obj.specific and not pointing_answer:
            self.dialogue = None
            self.count("dialogue_cancelled")
            self.log.info("'%s': the question %s is withdrawn", t.text, d.clarification_id)
            return []
        if not u.obj.specific and not pointing_answer:
            if u.answer == "confirm" and (d.reason == "low_confidence" or len(d.candidates) <= 1):
                draft = d.draft
                if draft.target is None and d.candidates:
                    draft.target = d.candidates[0]
                return [self._from_draft(t, draft, ctx, f"confirmed by '{t.text}' (question {d.clarification_id})",
                                         phrase=d.phrase)]
            self.count("dialogue_unresolved")
            return [self._reask(t, d, d.candidates)]
        pool = d.candidates if d.candidates and d.reason != "not_found" else ctx.objects or d.candidates
        scored = score(u.obj, pool, ctx.pointing, ctx.weights, adaptive=self.cfg.weights == "adaptive", ref=None)
        choice = choose(u.obj, scored, margin=self.cfg.margin, check_evidence=False)
        if choice.kind == "target" and choice.winner is not None:
            d.draft.target = choice.winner.obj
            why = f"'{t.text}' answered question {d.clarification_id}: " + describe.explain_target(
                choice.winner, choice.runner_up, ctx.weights.to_dict(), u.obj, None)
            return [self._from_draft(t, d.draft, ctx, why, confidence=choice.winner.total, phrase=d.phrase)]
        self.count("dialogue_unresolved")
        narrowed = [c.obj for c in choice.candidates] or d.candidates
        return [self._reask(t, d, narrowed)]

    def _other_answer(self, t: Transcript, u: Utterance, ctx: Context, d: Dialogue) -> list[Output]:
        """"The other one" / "not that one": every candidate but the one proposed, pointed at or acted on."""
        excluded: SceneObject | None = d.draft.target
        if excluded is None and u.obj.deictic and ctx.pointing is not None and d.candidates:
            pointed = score(ObjectPhrase(), d.candidates, ctx.pointing, Weights(speech=0.0, vision=0.0, gesture=1.0))
            if pointed and (pointed[0].gesture or 0.0) >= 0.5:
                excluded = pointed[0].obj
        if excluded is None and self.last is not None:
            excluded = self.last.target
        pool = d.candidates
        if len(pool) < 2 and excluded is not None:  # a yes/no question about one object: the others of its kind
            kind = d.phrase.label if d.phrase.label not in (None, ANY_OBJECT) else excluded.label
            pool = [o for o in ctx.objects if label_matches(kind, o.label)]
        remaining = [o for o in pool if excluded is None or o.key != excluded.key]
        if u.obj.specific:
            fit = [s.obj for s in score(u.obj, remaining, None, ctx.weights, adaptive=False) if s.match >= 0.5]
            remaining = fit or remaining
        if excluded is not None and len(remaining) == 1:
            d.draft.target = remaining[0]
            why = (f"'{t.text}' answered question {d.clarification_id}: not {excluded.id} ({excluded.name()}), "
                   f"so the other candidate {remaining[0].id} ({remaining[0].name()})")
            return [self._from_draft(t, d.draft, ctx, why, phrase=d.phrase)]
        self.count("dialogue_unresolved")
        d.draft.target = None
        return [self._reask(t, d, remaining if excluded is not None and remaining else pool)]

    def correct_last(self, t: Transcript, u: Utterance, ctx: Context) -> list[Output]:
        """"No, the other one" / "not that one" / "no, the blue one" just after a command: the same command on
        another object — of the same kind as the one acted on, unless the correction names another kind."""
        last = self.last
        assert last is not None
        self.last = None
        self.count("corrected_by_speech")
        kind = last.phrase.label if last.phrase.label not in (None, ANY_OBJECT) else last.target.label
        phrase = u.obj if u.obj.label not in (None, ANY_OBJECT) else replace(u.obj, label=kind, deictic=False)
        pool = [o for o in ctx.objects if o.key != last.target.key and label_matches(phrase.label, o.label)]
        draft = Draft(last.intent, f"{last.text} / {t.text}", place=last.place)
        scored = score(phrase, pool, None, ctx.weights, adaptive=self.cfg.weights == "adaptive", ref=ctx.ref)
        choice = choose(phrase, scored, margin=self.cfg.margin, check_evidence=False)
        if choice.kind == "target" and choice.winner is not None:
            draft.target = choice.winner.obj
            why = (f"'{t.text}' corrected '{last.text}': not {last.target.id} ({last.target.name()}); "
                   + describe.explain_target(choice.winner, choice.runner_up, ctx.weights.to_dict(), phrase, None))
            return [self._from_draft(t, draft, ctx, why, confidence=choice.winner.total, phrase=phrase)]
        if choice.kind != "ambiguous":
            choice = Choice("not_found", None, ())
        return [self._clarify(t, replace(u, obj=phrase), ctx, choice, draft)]

    def _reask(self, t: Transcript, d: Dialogue, candidates: list[SceneObject]) -> Output:
        scored = [Scored(o, 1.0, 1.0, 1.0, None, None, 1.0) for o in candidates]
        question = describe.ambiguous_question(d.phrase, scored) if len(candidates) > 1 else d.question
        clr = Clarification(stamp=t.stamp, source=self.source, id=stable_id("clr", t.source, t.stamp, t.mic),
                            text=t.text, reason=d.reason, question=question,
                            candidates=[o.to_target() for o in candidates[:MAX_CANDIDATES]])
        self.dialogue = Dialogue(clr.id, d.reason, d.draft, d.phrase, candidates, t.end + self.cfg.dialogue_timeout,
                                 question)
        return Output(clr)

    def _from_draft(self, t: Transcript, draft: Draft, ctx: Context, why: str, confidence: float | None = None,
                    phrase: ObjectPhrase | None = None) -> Output:
        self.dialogue = None
        target = draft.target
        if target is not None:  # "no, the other one" may follow
            self.last = LastCommand(draft.intent, draft.text, target, phrase or ObjectPhrase(), draft.place,
                                    t.end + self.cfg.dialogue_timeout)
        conf = confidence if confidence is not None else (ctx.reliabilities["speech"] or 0.0)
        text = f"{draft.text} / {t.text}"
        return Output(self._command(
            t, draft.intent, text=text, target=target.to_target() if target else None, location=draft.location,
            weights=ctx.weights, inputs=ctx.inputs, confidence=max(0.0, min(1.0, conf)), explanation=why,
            gesture="point" if ctx.pointing else None, place=draft.place, motion=draft.motion,
            prompt=self._prompt(text, draft.intent, target, draft.location, draft.place, ctx, why,
                                motion=draft.motion)))

    def _clarify(self, t: Transcript, u: Utterance, ctx: Context, choice: Choice, draft: Draft,
                 heard: bool = False) -> Output:
        if choice.kind == "conflict":
            question = describe.conflict_question(u.obj, choice.speech_best, choice.gesture_best)
            candidates = [c.obj for c in choice.candidates]
        elif choice.kind == "ambiguous":
            question = describe.ambiguous_question(u.obj, list(choice.candidates))
            candidates = [c.obj for c in choice.candidates]
        elif choice.kind == "low_confidence":
            question = describe.confirm_question(t.text, None if heard else choice.winner)
            candidates = [c.obj for c in choice.candidates]
        else:  # not_found: the answer may pick any visible object
            visible = sorted(ctx.objects, key=lambda o: (-o.score, o.cam, o.id))[:MAX_CANDIDATES]
            question = describe.not_found_question(u.obj, visible, "vision" in ctx.missing)
            candidates = visible
        clr = Clarification(stamp=t.stamp, source=self.source, id=stable_id("clr", t.source, t.stamp, t.mic),
                            text=t.text, reason=choice.kind, question=question,
                            candidates=[] if choice.kind == "not_found" else [o.to_target() for o in candidates])
        self.dialogue = Dialogue(clr.id, choice.kind, draft, u.obj, candidates, t.end + self.cfg.dialogue_timeout,
                                 question)
        self.count(f"clarification_{choice.kind}")
        return Output(clr)

    def _clarify_place(self, t: Transcript, u: Utterance, ctx: Context, draft: Draft) -> Output:
        question = "Where do you mean? Please point at the place." if u.deictic_place or not u.dest_obj else \
            f"I can't see the {u.dest_obj.describe()}. Where should I put it?"
        clr = Clarification(stamp=t.stamp, source=self.source, id=stable_id("clr", t.source, t.stamp, t.mic),
                            text=t.text, reason="not_found", question=question, candidates=[])
        self.dialogue = Dialogue(clr.id, "not_found", draft, ObjectPhrase(), [], t.end + self.cfg.dialogue_timeout,
                                 question)
        self.count("clarification_not_found")
        return Output(clr)

    # -- building samples -----------------------------------------------------
    def _prompt(self, text: str | None, intent: str, target: SceneObject | None, location: tuple | None,
                place: str | None, ctx: Context, why: str, motion: Motion | None = None) -> str:
        return describe.planner_prompt(text=text, intent=intent, target=target, location=location, place=place,
                                       pointing=ctx.pointing, gesture=None, objects=ctx.objects,
                                       missing=ctx.missing, explanation=why, motion=motion)

    def _target_command(self, t: Transcript, intent: str, target: Scored, location: tuple | None, ctx: Context,
                        explanation: str, place: str | None = None) -> Output:
        if ctx.missing:
            explanation += "; missing: " + ", ".join(ctx.missing) + f" (window closed by {ctx.how})"
        return Output(self._command(
            t, intent, target=target.obj.to_target(), location=location, weights=ctx.weights, inputs=ctx.inputs,
            confidence=max(0.0, min(1.0, target.total)), explanation=explanation,
            gesture="point" if target.gesture is not None else None, place=place,
            prompt=self._prompt(t.text, intent, target.obj, location, place, ctx, explanation)))

    def _command(self, t: Transcript, intent: str, *, weights: Weights, inputs: dict, confidence: float,
                 explanation: str, prompt: str, text: str | None = None, target=None, location=None,
                 gesture: str | None = None, place: str | None = None, motion: Motion | None = None) -> FusedCommand:
        loc = Location(x=float(location[0]), y=float(location[1]), cam=location[2]) if location else None
        wire_motion = WireMotion(direction=motion.direction, distance=motion.distance, angle=motion.angle) \
            if motion is not None else None
        return FusedCommand(stamp=t.stamp, source=self.source, id=stable_id("cmd", t.source, t.stamp, t.mic),
                            intent=intent, text=text if text is not None else t.text, target=target, location=loc,
                            place=place, gesture=gesture, confidence=round(max(0.0, min(1.0, confidence)), 4), weights=weights,
                            inputs=inputs, explanation=explanation, prompt=prompt, motion=wire_motion)

    def _gesture_command(self, ev: GestureEvent, intent: str, realtime: bool, why: str) -> Output:
        prompt = describe.planner_prompt(text=None, intent=intent, target=None, location=None, place=None,
                                         pointing=None, gesture=f"{ev.gesture} ({ev.hand} hand)", objects=[],
                                         missing=[], explanation=why)
        cmd = FusedCommand(stamp=ev.stamp, source=self.source, id=stable_id("cmd", ev.source, ev.stamp, ev.gesture),
                           intent=intent, text=None, target=None, location=None, gesture=ev.gesture,
                           confidence=round(ev.score, 4), weights=Weights(speech=0.0, vision=0.0, gesture=1.0),
                           inputs={"speech": None, "vision": None, "gesture": ev.stamp}, explanation=why,
                           prompt=prompt)
        self.count(f"gesture_{intent}")
        return Output(cmd, realtime=realtime)

    def memory_items(self) -> int:
        """Buffered samples plus bookkeeping (for the benchmark's flat-memory check)."""
        return self.streams.size() + len(self.pending) + len(self.seen_transcripts) + len(self.episodes)
