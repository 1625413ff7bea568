"""The clarification dialogue: a small state machine over the open question and the last command acted on.

States: nothing open; a `Question` open (until answered, withdrawn, superseded by a new command or a stop, or
`timeout` s of source time after it was asked: after the robot finished saying it, when its voice said when
(`spoken`); what was begun before that is no answer); a `LastCommand` remembered for as long ("no, the other one"
corrects it). Transitions return what to publish:
- `clarify` / `clarify_place` ask (a Clarification) and open the question with the command drafted so far;
- `reply` takes an utterance without an intent: an answer resolves the question into the drafted command,
  re-asks with the candidates narrowed, or withdraws it ("no"); a correction re-does the last command on
  another object.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, replace
from typing import Callable

from common.counters import CLARIFICATION_COUNTER, FusionCounter
from common.language import ANY_OBJECT, label_matches
from common.schema import SPEECH, VISION, ClarificationReason, FusedCommand, Intent, Spoken, Transcript, as_intent
from services.fusion import describe
from services.fusion.afford import VERBS
from services.fusion.decision import Act, Draft
from services.fusion.ground import MAX_CANDIDATES, Choice, SceneObject, Scored, best_pointed, score
from services.fusion.outputs import Output, Outputs
from services.fusion.parse import ObjectPhrase, Utterance
from services.fusion.window import Context


@dataclass
class LastCommand:
    """The latest command that acted on an object: "no, the other one" corrects it."""

    intent: Intent
    text: str
    target: SceneObject
    phrase: ObjectPhrase
    place: str | None
    expires: float  # source time


@dataclass
class Question:
    """The open clarification."""

    clarification_id: str
    reason: ClarificationReason
    draft: Draft
    phrase: ObjectPhrase
    candidates: list[SceneObject]
    expires: float  # source time
    question: str
    # source time the robot finished saying it (its voice's Spoken `end`): the answer window opens then; None: not
    # said aloud (no voice, or not yet), the window is open from the question on, as without a voice
    opens: float | None = None


class Dialogue:
    def __init__(
        self,
        outputs: Outputs,
        timeout: float,
        count: Callable[[FusionCounter], None],
        log: logging.Logger,
        doubt: float = 0.0,
    ):
        self.outputs = outputs
        self.timeout = timeout  # s of source time a question (or a command to correct) stays open
        # a "yes" heard with a speech reliability below this does not confirm: the question is asked again
        # (a one-word utterance may be a word the speech service only guessed to be "sure"; docs/fusion.md)
        self.doubt = doubt
        self.count = count
        self.log = log
        self.question: Question | None = None
        self.last: LastCommand | None = None

    # -- transitions without output ------------------------------------------------
    def close(self) -> None:
        """A stop closes the question."""
        self.question = None

    def supersede(self) -> None:
        """A new command replaces the question and is no longer a correction of the last one."""
        self.question = None
        self.last = None

    def expire(self, said_at: float) -> None:
        """What is older than the timeout at `said_at` (an utterance's start) is over."""
        if self.question is not None and said_at > self.question.expires:
            self.count("dialogue_expired")
            self.question = None
        if self.last is not None and said_at > self.last.expires:
            self.last = None

    def spoken(self, said: Spoken) -> bool:
        """The robot's voice said the open question aloud (`said.answers` is its id): the answer window opens at the
        end of what was said and stays open `timeout` s from there, not from the words that raised the question
        (a slow synthesis or a long question leaves the person the same time). A cut-short question (a stop) sends
        its Spoken again with the earlier end: the latest counts. False: `said` is not about the open question."""
        q = self.question
        if q is None or said.answers != q.clarification_id:
            return False
        q.opens = said.end
        q.expires = said.end + self.timeout
        return True

    def acted(
        self, t: Transcript, intent: Intent, text: str, target: SceneObject, phrase: ObjectPhrase, place: str | None
    ) -> None:
        """A command acted on `target`: "no, the other one" may follow."""
        self.last = LastCommand(intent, text, target, phrase, place, t.end + self.timeout)

    # -- asking ---------------------------------------------------------------------
    def clarify(
        self, t: Transcript, u: Utterance, ctx: Context, choice: Choice, draft: Draft, heard: bool = False
    ) -> Output:
        """Ask about the object of `draft`: which one (ambiguous, conflict), did you say (low confidence), or what
        (not found: the answer may pick any visible object)."""
        if choice.kind == "target":
            raise ValueError("clarify: the choice found its target, there is nothing to ask")
        if choice.kind == "conflict":
            assert choice.speech_best is not None and choice.gesture_best is not None  # the two sides (choose)
            question = describe.conflict_question(u.obj, choice.speech_best, choice.gesture_best)
            candidates = [c.obj for c in choice.candidates]
        elif choice.kind == "ambiguous":
            question = describe.ambiguous_question(u.obj, list(choice.candidates), ctx.objects)
            candidates = [c.obj for c in choice.candidates]
        elif choice.kind == "low_confidence":
            question = describe.confirm_question(t.text, None if heard else choice.winner)
            candidates = [c.obj for c in choice.candidates]
        else:
            visible = sorted(ctx.pool, key=lambda o: (-o.score, o.cam, o.id))[:MAX_CANDIDATES]
            nothing_to = VERBS.get(draft.intent, "do that to") if ctx.objects and not ctx.pool else None
            question = describe.not_found_question(u.obj, visible, VISION in ctx.missing, nothing_to)
            candidates = visible
        return self._ask(
            t, choice.kind, draft, u.obj, [] if choice.kind == "not_found" else candidates, candidates, question
        )

    def confirm_addressed(self, t: Transcript, cmd: FusedCommand, scene: list[SceneObject]) -> Output:
        """A command said while facing away from the robot: "Did you say that to me?" A yes acts on it."""
        return self.confirm(t, cmd, scene, f'You were facing away from me. Did you say that to me: "{t.text}"?')

    def confirm(self, t: Transcript, cmd: FusedCommand, scene: list[SceneObject], question: str) -> Output:
        """Ask `question` (yes or no) before `cmd` is published: a yes publishes it (a `low_confidence` question)."""
        target = next(
            (o for o in scene if cmd.target is not None and (o.id, o.cam) == (cmd.target.id, cmd.target.cam)), None
        )
        intent = as_intent(cmd.intent)  # a command fusion built: one of the contract's intents
        draft = Draft(intent, t.text, target=target, location=cmd.location, place=cmd.place, motion=cmd.motion)
        self.last = None  # nothing was acted on: there is no command to correct
        shown = [target] if target is not None else []
        return self._ask(t, "low_confidence", draft, ObjectPhrase(), shown, shown, question)

    def confirm_over_stop(self, t: Transcript, intent: Intent) -> Output:
        """A stop shown to the robot while "come here" was said (issue #40): the robot stopped; ask before coming."""
        question = f'You showed me a stop sign while saying "{t.text}". Should I do it?'
        self.last = None
        return self._ask(t, "conflict", Draft(intent, t.text), ObjectPhrase(), [], [], question)

    def refuse(self, t: Transcript, u: Utterance, answer: str, draft: Draft) -> Output:
        """ "I can't pick up a couch.": the words name only what the action cannot apply to (services/fusion/afford.py).
        On the wire a `not_found` Clarification without candidates (v1: no new reason value, docs/fusion.md); it stays
        open like one, so "the cup then" still picks the cup up."""
        return self._ask(t, "not_found", draft, u.obj, [], [], answer)

    def clarify_place(self, t: Transcript, u: Utterance, draft: Draft) -> Output:
        question = (
            "Where do you mean? Please point at the place."
            if u.deictic_place or not u.dest_obj
            else f"I can't see the {u.dest_obj.describe()}. Where should I put it?"
        )
        return self._ask(t, "not_found", draft, ObjectPhrase(), [], [], question)

    def _ask(
        self,
        t: Transcript,
        reason: ClarificationReason,
        draft: Draft,
        phrase: ObjectPhrase,
        shown: list[SceneObject],
        candidates: list[SceneObject],
        question: str,
    ) -> Output:
        out = self.outputs.clarification(t, reason, question, shown)
        self.question = Question(out.sample.id, reason, draft, phrase, candidates, t.end + self.timeout, question)
        self.count(CLARIFICATION_COUNTER[reason])
        return out

    def _reask(
        self,
        t: Transcript,
        q: Question,
        candidates: list[SceneObject],
        scene: list[SceneObject] | None = None,
        doubted: str | None = None,
    ) -> Output:
        """Ask `q` again (about `candidates`); `doubted`: the answer was heard too unsurely to count, said so."""
        self.count("dialogue_unresolved")
        if doubted is not None:
            question = f"I am not sure I heard '{doubted}'. {q.question}"
        elif len(candidates) > 1:
            scored = [Scored(o, 1.0, 1.0, 1.0, None, None, 1.0) for o in candidates]
            question = describe.ambiguous_question(q.phrase, scored, scene)
        else:
            question = q.question
        out = self.outputs.clarification(t, q.reason, question, candidates)
        self.question = Question(out.sample.id, q.reason, q.draft, q.phrase, candidates, t.end + self.timeout, question)
        return out

    # -- answers and corrections -------------------------------------------------------
    def reply(self, t: Transcript, u: Utterance, ctx: Context) -> list[Output] | None:
        """An utterance without an intent: the answer to the open question, a correction of the last command, or
        None when it is neither."""
        q = self.question
        if q is not None and (u.has_content or ctx.pointing is not None):
            if q.opens is not None and t.start < q.opens:  # begun while the robot was still asking: no answer
                self.count("answer_before_spoken")
                self.log.info(
                    "'%s' began %.2f s before the robot finished asking %s: not taken as its answer",
                    t.text,
                    q.opens - t.start,
                    q.clarification_id,
                )
                return []
            return self._answer(t, u, ctx, q)
        if self.last is not None and (u.other or (u.answer == "deny" and u.obj.specific)):
            return self._correct_last(t, u, ctx, self.last)
        return None

    def _answer(self, t: Transcript, u: Utterance, ctx: Context, q: Question) -> list[Output]:
        if u.other:
            return self._other_answer(t, u, ctx, q)
        pointing_answer = u.obj.deictic or (ctx.pointing is not None and not u.obj.specific)
        if u.answer == "deny" and not u.obj.specific and not pointing_answer:
            self.question = None
            self.count("dialogue_cancelled")
            self.log.info("'%s': the question %s is withdrawn", t.text, q.clarification_id)
            return []
        if not u.obj.specific and not pointing_answer:
            if u.answer == "confirm" and (q.reason == "low_confidence" or len(q.candidates) <= 1):
                heard = ctx.reliabilities[SPEECH]
                if heard is not None and heard < self.doubt:
                    self.count("dialogue_doubted_confirm")
                    self.log.info("'%s' (speech %.2f) is too doubtful to confirm %s", t.text, heard, q.clarification_id)
                    return [self._reask(t, q, q.candidates, ctx.objects, doubted=t.text)]
                draft = q.draft
                if draft.target is None and q.candidates:
                    draft.target = q.candidates[0]
                return [
                    self._from_draft(
                        t, draft, ctx, f"confirmed by '{t.text}' (question {q.clarification_id})", phrase=q.phrase
                    )
                ]
            return [self._reask(t, q, q.candidates, ctx.objects)]
        pool = q.candidates if q.candidates and q.reason != "not_found" else ctx.pool or q.candidates
        choice = ctx.choose(u.obj, pool, ctx.pointing, None, check_evidence=False)
        if choice.kind == "target" and choice.winner is not None:
            q.draft.target = choice.winner.obj
            why = f"'{t.text}' answered question {q.clarification_id}: " + describe.explain_target(
                choice.winner, choice.runner_up, ctx.weights.to_dict(), u.obj, None
            )
            return [self._from_draft(t, q.draft, ctx, why, confidence=choice.winner.total, phrase=q.phrase)]
        return [self._reask(t, q, [c.obj for c in choice.candidates] or q.candidates, ctx.objects)]

    def _other_answer(self, t: Transcript, u: Utterance, ctx: Context, q: Question) -> list[Output]:
        """ "The other one" / "not that one": every candidate but the one proposed, pointed at or acted on."""
        excluded: SceneObject | None = q.draft.target
        if excluded is None and u.obj.deictic and ctx.pointing is not None and q.candidates:
            pointed = best_pointed(ctx.pointing, q.candidates)
            if pointed is not None and (pointed.gesture or 0.0) >= 0.5:
                excluded = pointed.obj
        if excluded is None and self.last is not None:
            excluded = self.last.target
        pool = q.candidates
        if len(pool) < 2 and excluded is not None:  # a yes/no question about one object: the others of its kind
            kind = q.phrase.label if q.phrase.label not in (None, ANY_OBJECT) else excluded.label
            pool = [o for o in ctx.pool if label_matches(kind, o.label)]
        remaining = [o for o in pool if excluded is None or o.key != excluded.key]
        if u.obj.specific:
            fit = [
                s.obj
                for s in score(u.obj, remaining, None, ctx.weights, adaptive=False, scene=ctx.objects)
                if s.match >= 0.5
            ]
            remaining = fit or remaining
        if excluded is not None and len(remaining) == 1:
            q.draft.target = remaining[0]
            why = (
                f"'{t.text}' answered question {q.clarification_id}: not {excluded.id} ({excluded.name()}), "
                f"so the other candidate {remaining[0].id} ({remaining[0].name()})"
            )
            return [self._from_draft(t, q.draft, ctx, why, phrase=q.phrase)]
        q.draft.target = None
        return [self._reask(t, q, remaining if excluded is not None and remaining else pool, ctx.objects)]

    def _correct_last(self, t: Transcript, u: Utterance, ctx: Context, last: LastCommand) -> list[Output]:
        """ "No, the other one" / "not that one" / "no, the blue one" just after a command: the same command on
        another object — of the same kind as the one acted on, unless the correction names another kind."""
        self.last = None
        self.count("corrected_by_speech")
        kind = last.phrase.label if last.phrase.label not in (None, ANY_OBJECT) else last.target.label
        phrase = u.obj if u.obj.label not in (None, ANY_OBJECT) else replace(u.obj, label=kind, deictic=False)
        pool = [o for o in ctx.pool if o.key != last.target.key and label_matches(phrase.label, o.label)]
        draft = Draft(last.intent, f"{last.text} / {t.text}", place=last.place)
        choice = ctx.choose(phrase, pool, None, ctx.ref, check_evidence=False)
        if choice.kind == "target" and choice.winner is not None:
            draft.target = choice.winner.obj
            why = (
                f"'{t.text}' corrected '{last.text}': not {last.target.id} ({last.target.name()}); "
                + describe.explain_target(choice.winner, choice.runner_up, ctx.weights.to_dict(), phrase, None)
            )
            return [self._from_draft(t, draft, ctx, why, confidence=choice.winner.total, phrase=phrase)]
        if choice.kind != "ambiguous":
            choice = Choice("not_found", None, ())
        return [self.clarify(t, replace(u, obj=phrase), ctx, choice, draft)]

    def _from_draft(
        self,
        t: Transcript,
        draft: Draft,
        ctx: Context,
        why: str,
        confidence: float | None = None,
        phrase: ObjectPhrase | None = None,
    ) -> Output:
        """The drafted command, now decided: the question is over."""
        self.question = None
        if draft.target is not None:
            self.acted(t, draft.intent, draft.text, draft.target, phrase or ObjectPhrase(), draft.place)
        conf = confidence if confidence is not None else (ctx.reliabilities[SPEECH] or 0.0)
        act = Act(
            draft.intent,
            confidence=conf,
            explanation=why,
            text=f"{draft.text} / {t.text}",
            target=draft.target,
            location=draft.location,
            gesture="point" if ctx.pointing else None,
            place=draft.place,
            motion=draft.motion,
            motion_said=draft.motion_said,
        )
        return self.outputs.command(t, act, ctx)
