"""The fusion core: feeds the join, decides each closed window, and says what to publish.

A plain object driven by the service's single worker thread (no locks, no zenoh): feed it
samples with `on_*`, call `tick(wall)` regularly, publish what they return. Every decision is a
function of the samples' source stamps; wall time only decides *when* a window is closed (the
`max_wait` deadline) and which modalities are live. The jobs it delegates, each in its own file:
`join` (buffers, watermarks, when a window is ready), `window` (what a closed window holds),
`gestures` (gesture episodes, stop and wave memory), `dialogue` (the open question, answers,
corrections), `outputs` (the FusedCommand / Clarification builder), `ground` (which object).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, replace
from typing import Callable

import msgspec

from common.counters import GESTURE_COMMAND_COUNTER, SPEAKER_COUNTER, FusionCounter
from common.engagement import EngagementConfig
from common.language import ANY_OBJECT, PLACE_AS_OBJECT
from common.robot import DEFAULT, Profile, with_base
from common.schema import (
    GESTURE,
    SPEECH,
    VISION,
    Bodies,
    Detections,
    Faces,
    FusedCommand,
    GestureEvent,
    Hands,
    Intent,
    Location,
    Persons,
    RobotState,
    Speaker,
    Spoken,
    Transcript,
)
from common.settings import setting
from common.stack import node, publishers_of
from services.fusion import attention, describe, people, robot, space
from services.fusion.afford import Applicable, applicable, refusal, removed_words, unable
from services.fusion.decision import Act, ActOnTarget, Ask, Decision, Draft, Grounded, Ignore, Refuse
from services.fusion.dialogue import Dialogue
from services.fusion.gestures import CONTRARY_TO_STOP, Gestures, Person
from services.fusion.ground import DEFAULT_MARGIN, Choice, Scored, pointed_location, score
from services.fusion.join import Join, Ready, SeenOnce
from services.fusion.outputs import Output, Outputs
from services.fusion.parse import ObjectPhrase, Utterance, parse, stop_near_miss
from services.fusion.speaker import FaceHistory, SpeakerConfig, attribute
from services.fusion.window import Context, PendingTranscript, gather

TARGET_INTENTS: tuple[Intent, ...] = ("pick_up", "bring")  # must name an object


@dataclass
class Config:
    """Fusion's settings; each is also a flag of `hri-fusion` (common/settings.py, docs/fusion.md "Settings")."""

    window_before: float = setting(
        1.0,
        "seconds of source time before the utterance start searched for gestures and objects",
        at_least=0,
        metavar="S",
    )
    window_after: float = setting(
        0.3,
        "seconds after the utterance end searched: a point may come just after the word (not for words that name "
        "nothing to look at: a motion, come here, a greeting, an answer)",
        at_least=0,
        metavar="S",
    )
    max_wait: float = setting(
        0.5, "wall seconds after a transcript arrives before deciding with what is there", at_least=0, metavar="S"
    )
    weights: str = setting(
        "adaptive",
        "modality weights from each modality's evidence (adaptive) or constant (fixed)",
        choices=("adaptive", "fixed"),
    )
    fallback_most_confident: bool = setting(
        False,
        "when nothing matches the words, act on the most confident detection instead of asking "
        "(acting on the wrong object is worse than asking)",
    )
    dialogue_timeout: float = setting(
        10.0, "seconds of source time a clarification question stays open for an answer", at_least=0, metavar="S"
    )
    live_recent_s: float = setting(
        2.0,
        "a modality that sent a sample this many wall seconds ago is live without a liveliness token",
        at_least=0,
        metavar="S",
        flag="--live-recent",
    )
    horizon: float = setting(30.0, "seconds of source time kept per input stream", above=0, metavar="S")
    vision_lookback: float = setting(
        2.0, "detections this many seconds older than the window still describe the scene", at_least=0, metavar="S"
    )
    margin: float = setting(
        DEFAULT_MARGIN,
        "the lead of the best object's score over the runner-up's needed to act without asking",
        at_least=0,
        at_most=1,
    )
    low_speech_confidence: float = setting(
        0.3,
        "speech confidence below which fusion confirms before acting (unless pointing carries the choice), "
        "and below which a 'yes' is too doubtful to confirm",
        at_least=0,
        at_most=1,
        metavar="P",
    )
    gesture_min_score: float = setting(
        0.5, "open_palm and wave events scored below this are ignored", at_least=0, at_most=1, metavar="P"
    )
    episode_gap: float = setting(
        1.5, "seconds: events of one gesture this close belong to one episode (one command)", at_least=0, metavar="S"
    )
    confirm_unaddressed: bool = setting(
        True,
        "a command said while the speaker faced away from the robot (Speaker.addressed false) is asked about "
        "before it is acted on (--no-confirm-unaddressed: act on it)",
    )


def input_services(fusion: str = "fusion") -> tuple[str, ...]:
    """The services that publish one of the fusion node's modality inputs (common/stack.py): speech, vision, gesture.
    Each is a modality, named after its service, whose liveliness token counts."""
    return tuple(dict.fromkeys(p for i in node(fusion).inputs if i.modality for p in publishers_of(i.topic)))


MODALITIES = input_services()


def modality_of(service: str) -> str | None:
    """The modality a service's liveliness token speaks for: the service itself if it feeds fusion, else None."""
    return service if service in MODALITIES else None


def wanted(intent: Intent, u: Utterance) -> tuple[bool, bool]:
    """(the command needs an object, the command needs a location): from the intent and what was said."""
    named = u.obj.specific or u.obj.noun is not None
    wants_object = (
        intent in TARGET_INTENTS
        or (intent in ("look_at", "follow") and (named or u.obj.deictic))
        or (intent == "go_to" and named)
    )
    wants_location = (intent == "go_to" and not wants_object and not u.place) or (
        intent in ("put_down", "look_at") and not wants_object and bool(u.deictic_place or u.dest_obj)
    )
    return wants_object, wants_location


def unseen_pointing(phrase: ObjectPhrase, winner: Scored) -> bool:
    """ "That one" / "this" (deixis naming no kind) chose `winner` without pointing at it: no ray was seen, or the
    ray is near nothing. Then only the absence of other candidates chose it, and the point may have been at something
    vision does not see."""
    names_kind = phrase.label not in (None, ANY_OBJECT) or bool(phrase.color) or bool(phrase.spatial)
    return phrase.deictic and not names_kind and not phrase.relations and (winner.gesture or 0.0) < 0.5


@dataclass(frozen=True)
class Decided:
    """A decision with what it was made from: the utterance as understood then (re-parsed with the labels in view,
    sides in the camera's words), the window (its candidates: what the action may apply to) and what the
    affordances removed (said back in the explanation)."""

    utterance: Utterance
    decision: Decision
    ctx: Context
    found: Applicable | None = None
    to_recipient: bool = False  # a new command: "bring it to me" sends it to the person named


class FusionCore:
    def __init__(
        self,
        config: Config,
        source: str,
        count: Callable[[FusionCounter], None] = lambda name: None,
        log: logging.Logger | None = None,
        speaker: SpeakerConfig | None = None,
        profile: Profile = DEFAULT,
        engagement: EngagementConfig | None = None,
    ):
        self.cfg = config
        self.profile = profile  # what this robot can do (common/robot.py, docs/robot.md)
        self.robot = robot.RobotNow()  # what it is doing: unknown until a RobotState arrives
        self.speaker_cfg = speaker or SpeakerConfig()
        self.engagement_cfg = engagement or EngagementConfig()
        self.faces = FaceHistory(config.horizon)  # who is speaking: mouths over time (issue #33)
        self.source = source
        self.count = count
        self.log = log or logging.getLogger("hri.fusion.core")
        self.join: Join[PendingTranscript] = Join(
            config.horizon, config.vision_lookback, config.max_wait, config.live_recent_s
        )
        self.gestures = Gestures(config.gesture_min_score, config.episode_gap, config.horizon)
        self.outputs = Outputs(source)
        self.outputs.robot = self._robot_lines()
        self.outputs.mount = profile.camera  # targets and locations also in the robot's base frame (docs/robot.md)
        self.dialogue = Dialogue(
            self.outputs, config.dialogue_timeout, self.count, self.log, doubt=config.low_speech_confidence
        )
        self.seen_transcripts = SeenOnce(config.horizon)
        self.facing = space.Facing()  # which way the speaker faces: "on my left"
        # people (issue #33): who said an utterance (the person id of its Speaker, decided once when its window
        # closes; None = unknown) and the persons in view, for "bring it to me"
        self.speaker_of: Callable[[PendingTranscript], str | None] = self._decided_speaker
        self.deciding: tuple[PendingTranscript, Speaker | None] | None = None  # the window in decide() and its speaker
        self.persons: list[Persons] = []

    # -- inputs ---------------------------------------------------------------
    def _add(self, modality: str, key: str, stamp: float, item: object, wall: float, ident: object = None) -> bool:
        status = self.join.add(modality, key, stamp, item, wall, ident)
        if status in ("duplicate", "late"):
            self.count(status)
            return False
        if status == "reset":
            self.count("timeline_reset")
            self.log.info(
                "%s went back in time (consistent samples older than the %.0f s horizon: a replay "
                "restarted or a clock stepped back): buffer for %s restarted",
                key,
                self.cfg.horizon,
                modality,
            )
        return True

    def on_detections(self, key: str, det: Detections, wall: float) -> list[Output]:
        self._add(VISION, key, det.stamp, det, wall)
        return []

    def on_hands(self, key: str, hands: Hands, wall: float) -> list[Output]:
        self._add(GESTURE, key, hands.stamp, hands, wall)
        return []

    def on_bodies(self, key: str, bodies: Bodies, wall: float) -> list[Output]:
        self.facing.add(bodies)
        return []

    def on_faces(self, key: str, faces: Faces, wall: float) -> list[Output]:
        if not self.faces.add(faces):
            self.count("late")
        return []

    def on_persons(self, key: str, persons: Persons, wall: float) -> list[Output]:
        self.persons = [s for s in self.persons if s.stamp >= persons.stamp - self.cfg.horizon][-299:] + [persons]
        return []

    def on_robot_state(self, key: str, state: RobotState, wall: float) -> list[Output]:
        """The robot's state: kept for the next commands; a failure is announced; a queued command goes out once the
        robot is idle or done (services/fusion/robot.py)."""
        if not self.robot.update(state):
            self.count("late")
            return []
        self.count("robot_states")
        self.outputs.robot = self._robot_lines()
        out: list[Output] = []
        failed = self.robot.failure()
        if failed is not None:
            self.count("robot_failure_announced")
            out.append(self.outputs.announcement(state, failed, self.robot.command(state)))
        queued = self.robot.release()
        if queued is not None:
            self.count("released_after_busy")
            self.log.info("robot %s: queued command %s %s goes out", state.status, queued.id, queued.intent)
            self.robot.remember(queued)
            out.append(Output(queued))
        return out

    def on_spoken(self, key: str, said: Spoken, wall: float) -> list[Output]:
        """What the robot's voice said and when: a question said aloud is answered by what the person says after it
        ended (services/fusion/dialogue.py `Dialogue.spoken`). Not a modality: nothing is weighed or waited for."""
        if self.dialogue.spoken(said):
            self.count("question_spoken")
        return []

    def _drop_queued(self) -> None:
        """A stop also cancels what waits for the robot to be free (a stop never means "later")."""
        dropped = self.robot.drop_queued()
        if dropped:
            self.count("queue_dropped_by_stop")
            self.log.info("stop: %d command(s) queued while busy dropped", dropped)

    def _robot_lines(self) -> list[str]:
        """The planner prompt's lines about the robot: none for the default profile and no state heard (as before)."""
        lines = [] if self.profile.is_default else [f"Robot: {self.profile.words()}"]
        state = self.robot.words()
        return lines + ([f"Robot state: {state}"] if state else [])

    def on_gesture_event(self, key: str, ev: GestureEvent, wall: float) -> list[Output]:
        if not self._add(GESTURE, key, ev.stamp, ev, wall, ident=(ev.gesture, ev.phase, ev.hand)):
            return []
        command = self.gestures.on_event(key, ev, self.gesturer(ev))
        if command is None:
            return []
        if command.intent == "stop":
            self.dialogue.close()
            self._drop_queued()
        elif self.profile.missing_ability(command.intent) is not None:  # a wave to a robot that cannot come
            self.count("refused_ability")
            self.log.info("%s by gesture: %s", command.intent, self.profile.missing_ability(command.intent))
            return []
        self.count(GESTURE_COMMAND_COUNTER[command.intent])
        return [self.outputs.gesture_command(ev, command.intent, command.why, command.realtime)]

    def gesturer(self, ev: GestureEvent) -> Person:
        """What fusion knows of the person making a gesture at its time (services/fusion/attention.py)."""
        faces = self.faces.around(ev.stamp - attention.LOOK_BACK_S, ev.stamp)
        engaged = attention.engaged(self.persons, faces, ev.person, ev.stamp, self.engagement_cfg)
        still = self.speaker_cfg.speaker_still
        return Person(engaged, attention.speaking(self.persons, faces, ev.person, ev.stamp, still))

    def on_transcript(self, key: str, t: Transcript, wall: float) -> list[Output]:
        self.join.liveness.arrived(SPEECH, wall)
        if not t.final:
            self.count("partial_ignored")
            return []
        if not self.seen_transcripts.first((t.source, t.stamp), t.stamp):
            self.count("duplicate")
            return []
        u = parse(t.text)
        near = (
            None
            if u.intent == "stop"
            else stop_near_miss([(w.word, w.confidence) for w in t.words] or [(t.text, t.confidence)])
        )
        if u.intent == "stop" or near:  # no window to wait for: stop now
            self.dialogue.close()
            self._drop_queued()
            why = f"'{t.text}' asks to stop (speech confidence {t.confidence:.2f}); stopping never waits"
            if near:
                why += f"; '{near[0]}' was doubted by the recogniser and taken as '{near[1]}'"
            stop = Act("stop", confidence=t.confidence, explanation=why, realtime=True)
            return self.with_speaker(t, [self.outputs.command(t, stop, None)])
        after = self.cfg.window_after if u.looks_at_something else 0.0
        self.join.open(PendingTranscript(key, t, u, wall, t.start - self.cfg.window_before, t.end + after))
        return []

    def on_liveliness(self, service: str, instance: str, present: bool) -> None:
        modality = modality_of(service)
        if modality:
            self.join.liveness.token(modality, instance, present)

    # -- the join -------------------------------------------------------------
    def tick(self, wall: float) -> list[Output]:
        out: list[Output] = []
        for window, how in self.join.due(wall):
            speaker = self.attribute_speaker(window.transcript)
            self.deciding = (window, speaker)
            out.extend(self.with_speaker(window.transcript, self.decide(window, how, speaker), speaker))
        self.deciding = None
        for o in out:
            if isinstance(o.sample, FusedCommand):
                self.robot.remember(o.sample)
        return out

    # -- who is speaking (services/fusion/speaker.py) -------------------------------
    def _decided_speaker(self, p: PendingTranscript) -> str | None:
        """The person who said the utterance being decided (`speaker_of`), None when unknown."""
        if self.deciding is None or self.deciding[0] is not p or self.deciding[1] is None:
            return None
        return self.deciding[1].person

    def attribute_speaker(self, t: Transcript) -> Speaker | None:
        """Who said `t`; None when no face stage feeds fusion (nothing to judge from, as before issue #33)."""
        if not len(self.faces):
            return None
        margin = self.speaker_cfg.speaker_guard + self.speaker_cfg.speaker_context
        around = self.faces.around(t.start - margin, t.end + margin)
        speaker = attribute(t, around, self.speaker_cfg, self.engagement_cfg, self.persons)
        self.count(SPEAKER_COUNTER[speaker.method])
        return speaker

    def with_speaker(self, t: Transcript, outs: list[Output], speaker: Speaker | None = None) -> list[Output]:
        """Every command and question on `t` carries its speaker."""
        speaker = speaker if speaker is not None else self.attribute_speaker(t)
        for out in outs:
            out.sample.speaker = speaker
        return outs

    def confirm_unaddressed(
        self, t: Transcript, ctx: Context, speaker: Speaker | None, outs: list[Output]
    ) -> list[Output]:
        """A command said while its speaker faced away (to someone else, likely) is asked about first."""
        if not self.cfg.confirm_unaddressed or speaker is None or speaker.addressed is not False:
            return outs
        asked = [
            self.dialogue.confirm_addressed(t, out.sample, ctx.objects)
            if isinstance(out.sample, FusedCommand) and out.sample.intent != "stop"
            else out
            for out in outs
        ]
        if any(a is not o for a, o in zip(asked, outs)):
            self.count("unaddressed_confirm")
            self.log.info("'%s': %s faced away while saying it: asking first", t.text, speaker.person)
        return asked

    def context(self, p: PendingTranscript, how: Ready) -> Context:
        return gather(
            self.join.streams,
            p,
            how,
            weights_mode=self.cfg.weights,
            vision_lookback=self.cfg.vision_lookback,
            margin=self.cfg.margin,
            log=self.log,
            speaker_person=self.speaker_of(p),
        )

    # -- decisions ------------------------------------------------------------
    def decide(self, p: PendingTranscript, how: Ready, speaker: Speaker | None = None) -> list[Output]:
        """The window of an utterance is due: decide what to do (one Decision), then render it; a command said
        facing away (`speaker`, decided once per window in `tick`) is asked about first."""
        t = p.transcript
        if self.gestures.stop_given(t.start, p.hi):  # a deliberate stop while it was said (the robot stopped)
            if p.utterance.intent in CONTRARY_TO_STOP:
                self.count("stop_gesture_conflict")
                return [self.dialogue.confirm_over_stop(t, p.utterance.intent)]
            why = f"'{t.text}' cancelled: a stop was shown to the robot while it was said"
            return self.ignore(Ignore("cancelled_by_stop_gesture", why))
        if self.gestures.palm_seen(item for _, item in self.join.streams.between(GESTURE, t.start, p.hi)):
            self.count("palm_during_utterance")  # an open palm, not a stop shown to the robot: decided as usual
        ctx = self._with_persons(p.utterance, self.context(p, how))
        recipient = people.split_recipient(t.text)[1]  # "bring it to me": where it goes (the parse keeps "her")
        replied, decided = self.decide_utterance(p, ctx)
        if replied is not None:
            return replied
        assert decided is not None
        out = self.render(t, decided)
        if recipient is not None and decided.to_recipient:
            out = [self._to_recipient(o, recipient, p, ctx) for o in out]
        return self.hold_while_busy(t, ctx, self.confirm_unaddressed(t, ctx, speaker, out))

    def hold_while_busy(self, t: Transcript, ctx: Context, outs: list[Output]) -> list[Output]:
        """A new command while the robot is busy: asked about or queued, as the profile says (stop always passes)."""
        state = self.robot.state
        kept: list[Output] = []
        for out in outs:
            cmd = out.sample
            action = robot.while_busy(state, self.profile, cmd.intent) if isinstance(cmd, FusedCommand) else "act"
            if action == "act" or state is None or not isinstance(cmd, FusedCommand):
                kept.append(out)
            elif action == "queue":
                self.count("queued_while_busy")
                self.log.info("robot busy: %s %s queued until it is idle", cmd.intent, cmd.id)
                self.robot.queue(cmd)
            else:
                self.count("asked_while_busy")
                question = robot.busy_question(state, self.robot.command(state), cmd)
                kept.append(self.dialogue.confirm(t, cmd, ctx.objects, question))
        return kept

    def decide_utterance(self, p: PendingTranscript, ctx: Context) -> tuple[list[Output] | None, Decided | None]:
        """What to do with an utterance whose window is due: (the dialogue's own reply to an answer, None) or
        (None, the decision about the utterance as understood in this window)."""
        t, u = p.transcript, p.utterance
        if u.unknown and ctx.objects:  # a user's own label in view ("the widget") is a noun too
            u = parse(t.text, labels=tuple(sorted({o.label for o in ctx.objects})))
        self.dialogue.expire(t.start)
        if u.intent is None:
            reply = self.dialogue.reply(t, u, self._for_dialogue(ctx))
            if reply is not None:
                return reply, None
            # "the bottle behind the cup" names a thing: look at it. "The red one" names no kind: a late answer.
            if u.obj.names_kind and u.answer is None and not u.other:
                self.count("bare_reference")
                self.dialogue.supersede()
                return None, self.command(t, replace(u, intent="look_at"), ctx)
            return None, Decided(u, Ignore("ignored_no_intent", f"'{t.text}' is not a command I know; ignored"), ctx)
        self.dialogue.supersede()
        if u.intent == "come_here" and self.gestures.waved(p.lo, p.hi):
            return None, Decided(u, Ignore("duplicate_of_gesture"), ctx)
        person = self._person_decision(t, u, ctx, p)
        decided = Decided(u, person, ctx) if person is not None else self.command(t, u, ctx)
        return None, replace(decided, to_recipient=True)

    def _with_persons(self, u: Utterance, ctx: Context) -> Context:
        """ "The man on the left" with no person among the detections (the colour backend finds none): the persons
        in view (`Persons`, within the vision lookback of the utterance) are the candidates, by their ids."""
        if u.obj.label != "person":
            return ctx
        seen = people.latest_persons(self.persons, ctx.ref, self.cfg.vision_lookback)
        if seen is None or any(o.label == "person" and o.cam == seen.cam for o in ctx.objects):
            return ctx
        self.count("persons_as_candidates")
        return replace(ctx, objects=ctx.objects + [people.as_scene_object(q, seen) for q in seen.persons])

    def _person_decision(self, t: Transcript, u: Utterance, ctx: Context, p: PendingTranscript) -> Act | None:
        """ "Follow me", "look at him", "watch the person who is talking": the person in `Persons` (by their part in
        the talk: the speaker, the one other person) is the target; None when none is named or none resolves."""
        ref = people.person_referent(t.text) if u.intent in ("follow", "look_at") else None
        seen = people.latest_persons(self.persons, ctx.ref, self.cfg.vision_lookback) if ref is not None else None
        person = people.resolve(ref, seen.persons, self.speaker_of(p)) if ref is not None and seen else None
        if person is None or seen is None or ref is None:
            return None
        self.count("person_target")
        why = f"'{ref.said}' is {person.id}" + (" (the speaker)" if ref.who == "speaker" else " (the other person)")
        return Act(
            u.intent or "follow",
            confidence=ctx.reliabilities[SPEECH] or 0.0,
            explanation=why,
            target=people.as_scene_object(person, seen),
        )

    def _to_recipient(self, out: Output, ref: people.PersonRef, p: PendingTranscript, ctx: Context) -> Output:
        """A bring/give command goes to the person named ("to me": the speaker): their place is its `location`."""
        sample = out.sample
        if not isinstance(sample, FusedCommand) or sample.intent != "bring" or sample.location is not None:
            return out
        seen = people.latest_persons(self.persons, ctx.ref, self.cfg.vision_lookback)
        person = people.resolve(ref, seen.persons, self.speaker_of(p)) if seen else None
        if person is None or seen is None:
            self.count("recipient_unknown")
            return out
        why = f"; to {person.id} ('{ref.said}')" + (" at their torso in metres" if person.position else "")
        located = msgspec.structs.replace(
            sample,
            location=with_base(people.location_of(person, seen.cam), self.profile.camera),
            explanation=sample.explanation + why,
        )
        return replace(out, sample=located)

    def command(self, t: Transcript, u: Utterance, ctx: Context) -> Decided:
        """A command utterance: its words about sides turned into the camera's, a place that is a thing said as
        the thing, the window narrowed to what the action may apply to for this robot (services/fusion/afford.py);
        refused when the robot cannot do it at all; then decided, "put it down" on what the robot holds."""
        u = self._in_camera_words(t, u, ctx)
        intent = u.intent
        assert intent is not None
        if intent in TARGET_INTENTS and u.place in PLACE_AS_OBJECT and u.obj.label is None and not u.obj.deictic:
            # "pick up the table": what is picked up is the thing, not a place
            u = replace(u, obj=replace(u.obj, label=PLACE_AS_OBJECT[u.place]), place=None)
        found = applicable(intent, u.obj, ctx.objects, ctx.pointing, self.profile)
        ctx = replace(ctx, candidates=found.kept)  # nothing else is ever proposed (services/fusion/afford.py)
        cannot = unable(intent, self.profile)
        if cannot is not None:  # this robot cannot do it at all (its profile: no base, no carrying)
            self.count("refused_ability")
            return Decided(u, Refuse(cannot, Draft(intent, t.text, place=u.place)), ctx, found)
        decision = self.decide_command(t, u, ctx, found)
        if intent == "put_down":
            decision = self._put_down(t, u, ctx, decision)
        return Decided(u, decision, ctx, found)

    def _put_down(self, t: Transcript, u: Utterance, ctx: Context, decision: Decision) -> Decision:
        """ "Put it down there" with the robot's state known: what it holds (refused when it holds nothing)."""
        check = robot.put_down_check(self.robot.state, u.obj.label, ctx.objects)
        if check is None or isinstance(decision, (Ignore, Refuse)):
            return decision
        if check.refuse is not None:
            self.count("refused_not_holding")
            return Refuse(check.refuse, Draft("put_down", t.text, place=u.place))
        if not isinstance(decision, Act) or decision.target is not None or check.held is None:
            return decision
        target = check.in_view
        why = f"; it is {robot.held_words(check.held)}, which I hold" + ("" if target else " (out of view)")
        return replace(decision, target=target, explanation=decision.explanation + why)

    def decide_command(self, t: Transcript, u: Utterance, ctx: Context, found: Applicable) -> Decision:
        """A command utterance, grounded in its window: act, refuse, ask which / where / whether heard right."""
        intent = u.intent
        assert intent is not None
        wants_object, wants_location = wanted(intent, u)
        grounded = self._ground(t, u, ctx, wants_object, found)
        if not isinstance(grounded, Grounded):
            return grounded
        target = grounded.target
        location = None
        if wants_location:
            location = self._location(u, ctx)
            if location is None:
                return Ask(Draft(intent, t.text, target=target.obj if target else None), where=True)
        gesture_carried = (
            target is not None and (target.gesture or 0.0) >= 0.5 and ctx.weights.gesture >= ctx.weights.speech
        )
        if (ctx.reliabilities[SPEECH] or 0.0) < self.cfg.low_speech_confidence and not gesture_carried:
            draft = Draft(
                intent,
                t.text,
                target=target.obj if target else None,
                location=location,
                place=u.place,
                motion=u.motion,
                motion_said=u.motion_said,
            )
            return Ask(draft, Choice("low_confidence", target, (target,) if target else ()), heard=True)
        if target is not None:
            return ActOnTarget(intent, grounded, location, u.place)
        return Act(
            intent,
            confidence=ctx.reliabilities[SPEECH] or 0.0,
            explanation=describe.explain_command(t.text, intent, u, location),
            location=location,
            gesture="point" if location and ctx.pointing else None,
            place=u.place,
            motion=u.motion,
            motion_said=u.motion_said,
        )

    def _in_camera_words(self, t: Transcript, u: Utterance, ctx: Context) -> Utterance:
        spatial, why = self.facing.camera_words(u.obj.spatial, t.text, ctx.ref)
        if not why:
            return u
        # "on my left": the speaker's side, turned into the camera's
        self.count("speaker_side")
        self.log.info("'%s': %s", t.text, why)
        return replace(u, obj=replace(u.obj, spatial=spatial))

    def _ground(
        self, t: Transcript, u: Utterance, ctx: Context, wants_object: bool, found: Applicable
    ) -> Grounded | Decision:
        """The object the command is about: Grounded (possibly none), or the decision to refuse, ask or fall back."""
        intent = u.intent
        assert intent is not None
        if wants_object:
            return self._object(t, u, ctx, found)
        if intent == "put_down" and u.obj.specific:
            choice = self._choose(u.obj, ctx)  # the object may well be in the gripper, out of view: optional
            return Grounded(choice.winner if choice.kind == "target" else None)
        return Grounded()

    def _object(self, t: Transcript, u: Utterance, ctx: Context, found: Applicable) -> Grounded | Decision:
        """The object the command acts on, or instead: a refusal ("I can't pick up a couch."), a question, or the
        --fallback-most-confident command."""
        intent = u.intent
        assert intent is not None
        no = refusal(intent, u.obj, found, self.profile)
        if no is not None:
            self.count("refused_affordance")
            return Refuse(no, Draft(intent, t.text, place=u.place))
        if u.obj.noun is not None:  # a word I don't know: only a clear point can say which
            choice = self._choose(replace(u.obj, noun=None, color=None, label=None, spatial=(), deictic=True), ctx)
            if not (choice.kind == "target" and choice.winner is not None and (choice.winner.gesture or 0.0) >= 0.5):
                self.count("unknown_noun")
                return Ask(Draft(intent, t.text, place=u.place), Choice("not_found", None, ()))
            return Grounded(choice.winner, choice.runner_up, choice.overruled)
        choice = self._choose(u.obj, ctx)
        if choice.kind == "not_found" and self.cfg.fallback_most_confident and ctx.pool:
            best = max(ctx.pool, key=lambda o: (o.score, o.cam, o.id))
            scored = score(ObjectPhrase(), [best], None, ctx.weights, adaptive=False)[0]
            expl = (
                f"nothing fits '{u.obj.describe()}'; --fallback-most-confident picked the most confident "
                f"detection {best.id} ({best.name()}, score {best.score:.2f})"
            )
            return ActOnTarget(intent, Grounded(scored), None, u.place, explanation=expl, remember=False)
        if choice.kind == "target" and choice.winner is not None and unseen_pointing(u.obj, choice.winner):
            # "that one" said, no point seen (or none near anything) and no kind named: confirm, never guess
            self.count("deixis_unresolved")
            choice = replace(choice, kind="low_confidence")
        if choice.kind == "target":
            return Grounded(choice.winner, choice.runner_up, choice.overruled)
        target = choice.winner.obj if choice.kind == "low_confidence" and choice.winner else None
        return Ask(Draft(intent, t.text, target=target, place=u.place), choice)

    # -- rendering --------------------------------------------------------------
    def ignore(self, decision: Ignore) -> list[Output]:
        self.count(decision.reason)
        if decision.why:
            self.log.info("%s", decision.why)
        return []

    def render(self, t: Transcript, decided: Decided) -> list[Output]:
        """A decision into what is published (and what the dialogue remembers)."""
        u, ctx, decision = decided.utterance, decided.ctx, decided.decision
        if isinstance(decision, Ignore):
            return self.ignore(decision)
        if isinstance(decision, Refuse):
            return [self.dialogue.refuse(t, u, decision.answer, decision.draft)]
        if isinstance(decision, Ask):
            if decision.where:
                return [self.dialogue.clarify_place(t, u, decision.draft)]
            assert decision.choice is not None
            return [self.dialogue.clarify(t, u, ctx, decision.choice, decision.draft, heard=decision.heard)]
        if isinstance(decision, Act):
            return [self.outputs.command(t, decision, ctx)]
        target = decision.grounded.target
        assert target is not None
        expl = decision.explanation
        if expl is None:
            expl = self._explain_target(u, ctx, decision.grounded, decided.found)
        if decision.remember:
            self.dialogue.acted(t, decision.intent, t.text, target.obj, u.obj, decision.place)
        return [self.outputs.target_command(t, decision, ctx, expl)]

    def _explain_target(self, u: Utterance, ctx: Context, g: Grounded, found: Applicable | None) -> str:
        assert g.target is not None
        expl = describe.explain_target(g.target, g.runner_up, ctx.weights.to_dict(), u.obj, g.overruled)
        if found is not None:
            expl += removed_words(found, u.obj, ctx.pointing)
        if u.obj.noun is not None:
            expl += f" ('{u.obj.noun}' is not a word I know; the pointing decided)"
        if u.obj.unmatched:  # said back, never silently dropped
            expl += f" ('{' '.join(u.obj.unmatched)}' is not something I can check by sight)"
        return expl

    def _for_dialogue(self, ctx: Context) -> Context:
        """An answer or a correction chooses among what the asked (or corrected) command may act on."""
        q, last = self.dialogue.question, self.dialogue.last
        if q is not None:
            intent, phrase = q.draft.intent, q.phrase
        elif last is not None:
            intent, phrase = last.intent, last.phrase
        else:
            return ctx
        return replace(ctx, candidates=applicable(intent, phrase, ctx.objects, ctx.pointing, self.profile).kept)

    def _choose(self, phrase: ObjectPhrase, ctx: Context) -> Choice:
        return ctx.choose(phrase, ctx.pool, ctx.pointing, ctx.ref)

    def _location(self, u: Utterance, ctx: Context) -> Location | None:
        """Where the command goes: the object named as the destination ("put it on the red box"), else where the
        ray points; None without either. A place may be anything (a table, a couch) but the person pointing (nor what
        is on them: the ray starts inside their box)."""
        places = applicable("go_to", ObjectPhrase(), ctx.objects, ctx.pointing).kept
        if u.dest_obj is not None:
            choice = self._choose(u.dest_obj, replace(ctx, candidates=places))
            if choice.kind == "target" and choice.winner is not None:
                o = choice.winner.obj
                return Location(x=float(o.center[0]), y=float(o.center[1]), cam=o.cam)
        if ctx.pointing is None:
            return None
        return pointed_location(ctx.pointing, places)

    def memory_items(self) -> int:
        """Buffered samples plus bookkeeping (for the benchmark's flat-memory check)."""
        return self.join.streams.size() + len(self.join) + len(self.seen_transcripts) + len(self.gestures)
