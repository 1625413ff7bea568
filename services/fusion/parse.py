"""Reading an utterance with the one command language (common.language). Pure: no I/O, no zenoh.

The parser tags phrases greedily (longest phrase first) and then reads the tags:
the first intent is the command, colour/class/spatial/deictic words before a
destination marker describe the object, and what follows a destination marker
("on", "in", "there", a named place) describes where it goes. Words the language
does not know are matched fuzzily against its vocabulary (ASR slips such as
"pik up the rad cup"); every correction is recorded because it lowers the speech
reliability.
"""

from __future__ import annotations

import difflib
import re
from dataclasses import dataclass, field

from common import language as L

# Stop words win wherever they appear: a false stop is cheap, a missed one is not.
SAFETY_STOP_WORDS = ("stop", "halt", "freeze")
# Prepositions that start the destination of put_down ("put the cup ON the table").
DESTINATION_MARKERS = ("on", "in", "into", "onto", "next to", "near to", "inside", "at", "to")
FUZZY_MIN_LEN = 4  # shorter words are too easy to mis-correct ("a" -> "at")
FUZZY_CUTOFF = 0.75

_TABLES: tuple[tuple[str, dict[str, str]], ...] = (
    ("intent", L.phrases(L.INTENT_PHRASES)),
    ("answer", L.phrases(L.ANSWER_PHRASES)),
    ("spatial", L.phrases(L.SPATIAL_PHRASES)),
    ("place", L.phrases(L.PLACE_PHRASES)),
    ("object", L.phrases(L.OBJECT_PHRASES)),
    ("color", L.phrases(L.COLOR_PHRASES)),
)
_DEICTIC = {**{w: "object" for w in L.DEICTIC_OBJECT_WORDS}, **{w: "place" for w in L.DEICTIC_PLACE_WORDS}}
_FILLER = set(L.FILLER_WORDS)


def _phrase_index() -> dict[tuple[str, ...], tuple[str, str]]:
    """phrase tokens -> (kind, canonical). Earlier tables win on identical phrases."""
    index: dict[tuple[str, ...], tuple[str, str]] = {}
    for kind, table in _TABLES:
        for phrase, canonical in table.items():
            index.setdefault(tuple(phrase.split()), (kind, canonical))
    for word, kind in _DEICTIC.items():
        index.setdefault((word,), ("deictic_" + kind, word))
    for marker in DESTINATION_MARKERS:
        if len(marker.split()) > 1:
            index.setdefault(tuple(marker.split()), ("dest", marker))
    return index


PHRASES = _phrase_index()
MAX_PHRASE = max(len(p) for p in PHRASES)
# Content words the fuzzy matcher may correct to. Intent words need a closer match so that
# "want" does not become "wait" (= stop) while "grabb" still becomes "grab".
FUZZY_TARGETS = sorted({p[0] for p, (kind, _) in PHRASES.items() if len(p) == 1 and p[0] not in _FILLER
                        and kind in ("color", "object", "spatial", "place") and len(p[0]) >= 3})
FUZZY_INTENT_TARGETS = sorted({p[0] for p, (kind, _) in PHRASES.items() if len(p) == 1 and kind == "intent"
                               and len(p[0]) >= 4})
FUZZY_INTENT_CUTOFF = 0.85
# ASR sometimes glues a phrase into one word ("pickup", "putdown").
GLUED = {"".join(p): p for p in PHRASES if len(p) > 1}


@dataclass(frozen=True)
class Tag:
    kind: str  # intent, answer, spatial, place, object, color, deictic_object, deictic_place, dest
    value: str  # canonical name (or the deictic word itself)
    index: int  # position of the first token
    words: tuple[str, ...]  # the tokens as heard


@dataclass(frozen=True)
class ObjectPhrase:
    color: str | None = None
    label: str | None = None  # canonical class; None or "object" = any
    spatial: tuple[str, ...] = ()
    deictic: bool = False  # "this", "that", "it": a gesture (or the dialogue) should say which

    @property
    def specific(self) -> bool:
        """True if the words constrain which object (not just "it"/"that one")."""
        return bool(self.color or (self.label and self.label != "object") or self.spatial)

    def describe(self) -> str:
        words = [*self.spatial, self.color or "", self.label if self.label and self.label != "object" else "one"]
        return " ".join(w for w in words if w) if self.specific else ("that one" if self.deictic else "it")


@dataclass(frozen=True)
class Utterance:
    text: str
    tokens: tuple[str, ...]
    intent: str | None = None
    answer: str | None = None  # confirm / deny
    obj: ObjectPhrase = field(default_factory=ObjectPhrase)
    place: str | None = None  # a named place (table, kitchen …)
    deictic_place: str | None = None  # "there" / "here"
    dest_obj: ObjectPhrase | None = None  # "put it on the red box"
    corrections: tuple[tuple[str, str], ...] = ()  # (heard, understood) fuzzy matches
    unknown: tuple[str, ...] = ()  # content words nothing matched

    @property
    def has_content(self) -> bool:
        return bool(self.intent or self.answer or self.obj.specific or self.obj.deictic or self.place
                    or self.deictic_place)

    @property
    def deictic(self) -> bool:
        return self.obj.deictic or self.deictic_place is not None


def tokenize(text: str) -> list[str]:
    text = text.lower().replace("'", " ").replace("-", " ")
    tokens: list[str] = []
    for word in re.findall(r"[a-z]+", text):
        tokens.extend(GLUED.get(word, (word,)) if (word,) not in PHRASES else (word,))
    return tokens


def _fuzzy(token: str) -> str | None:
    if len(token) < FUZZY_MIN_LEN:
        return None
    match = (difflib.get_close_matches(token, FUZZY_INTENT_TARGETS, n=1, cutoff=FUZZY_INTENT_CUTOFF)
             or difflib.get_close_matches(token, FUZZY_TARGETS, n=1, cutoff=FUZZY_CUTOFF))
    return match[0] if match else None


def tag(tokens: list[str]) -> tuple[list[Tag], list[tuple[str, str]], list[str]]:
    """Greedy longest-phrase tagging with a fuzzy fallback for unknown single words."""
    tags: list[Tag] = []
    corrections: list[tuple[str, str]] = []
    unknown: list[str] = []
    toks = list(tokens)
    i = 0
    while i < len(toks):
        for n in range(min(MAX_PHRASE, len(toks) - i), 0, -1):
            hit = PHRASES.get(tuple(toks[i:i + n]))
            if hit is not None:
                tags.append(Tag(hit[0], hit[1], i, tuple(toks[i:i + n])))
                i += n
                break
        else:
            word = toks[i]
            if word in DESTINATION_MARKERS:
                tags.append(Tag("dest", word, i, (word,)))
            elif word not in _FILLER:
                fixed = _fuzzy(word)
                if fixed is not None:
                    corrections.append((word, fixed))
                    toks[i] = fixed
                    continue  # re-read with the correction (it may start a longer phrase)
                unknown.append(word)
            i += 1
    return tags, corrections, unknown


def _object_phrase(tags: list[Tag]) -> ObjectPhrase:
    color = next((t.value for t in tags if t.kind == "color"), None)
    label = next((t.value for t in tags if t.kind == "object"), None)
    spatial = tuple(dict.fromkeys(t.value for t in tags if t.kind == "spatial"))
    deictic = any(t.kind == "deictic_object" for t in tags)
    if label == "object" and any(t.kind == "deictic_object" for t in tags):
        label = None  # "that one": "one" is not a class
    return ObjectPhrase(color=color, label=label, spatial=spatial, deictic=deictic)


def parse(text: str) -> Utterance:
    tokens = tokenize(text)
    tags, corrections, unknown = tag(tokens)
    intents = [t for t in tags if t.kind == "intent"]
    intent = intents[0].value if intents else None
    if any(t.kind == "intent" and t.value == "stop" and t.words[0] in SAFETY_STOP_WORDS for t in tags):
        intent = "stop"
    answer_tag = next((t for t in tags if t.kind == "answer"), None)
    # Everything after the intent phrase; split object vs destination at the first marker.
    start = intents[0].index + len(intents[0].words) if intents else 0
    rest = [t for t in tags if t.index >= start and t.kind not in ("intent", "answer")]
    if intent == "put_down":  # "put <object> on|in|there <destination>"
        split = next((k for k, t in enumerate(rest) if t.kind in ("dest", "deictic_place", "place")), len(rest))
        obj_tags, dest_tags = rest[:split], rest[split:]
    else:  # the object phrase *is* the destination of go_to / look_at
        obj_tags, dest_tags = [t for t in rest if t.kind not in ("dest", "place", "deictic_place")], rest
    obj = _object_phrase(obj_tags)
    place = next((t.value for t in dest_tags if t.kind == "place"), None)
    deictic_place = next((t.value for t in dest_tags if t.kind == "deictic_place"), None)
    dest_obj = None
    if intent == "put_down":
        after_marker = [t for t in dest_tags if t.kind != "dest"]
        candidate = _object_phrase(after_marker)
        if candidate.specific:
            dest_obj = candidate
    return Utterance(text=text, tokens=tuple(tokens), intent=intent,
                     answer=answer_tag.value if answer_tag else None, obj=obj, place=place,
                     deictic_place=deictic_place, dest_obj=dest_obj, corrections=tuple(corrections),
                     unknown=tuple(unknown))
