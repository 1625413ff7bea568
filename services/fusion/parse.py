"""Reading an utterance with the one command language (common.language). Pure: no I/O, no zenoh.

Text arrives as Whisper prints it ("Could you, uh, hand me the blue pitcher, please?"): lower-cased,
punctuation dropped, numbers kept as digits. The parser tags phrases greedily (longest phrase
first) and then reads the tags: the first intent is the command (a greeting only when nothing else
is asked), colour/class/spatial/deictic words before a destination marker describe the object, and
what follows a destination marker ("on", "in", "there", a named place) describes where it goes.
A motion verb with a direction or an amount and no object is a motion ("go forward ten meters").
A relation word splits the object phrase: the words before it name the object (the head noun decides the kind:
"the bottle next to the bowl" is a bottle), the words after it the anchor ("next to the bowl"); ordinals ("the
second bottle from the left") and modifiers nothing can check ("the soap bottle", said back) are kept too.
A correction word after something was said ("the red, no, the blue cup") replaces what came before
it. An unknown word in a noun's place ("the blue pitcher") is kept as the noun, so the robot can say
it does not know it. Words the language does not know are matched fuzzily against its vocabulary
(ASR slips such as "pik up the rad cup"); every correction is recorded because it lowers the speech
reliability. Hesitations and politeness are tagged as filler and never change the meaning.
"""

from __future__ import annotations

import difflib
import re
from dataclasses import dataclass, field, replace
from typing import Literal, cast

from common import language as L
from common.schema import Intent, Motion, MotionDirection, as_intent

# Stop words win wherever they appear: a false stop is cheap, a missed one is not (stop_requested).
SAFETY_STOP_WORDS = L.STOP_WORDS
# Prepositions that start the destination of put_down ("put the cup ON the table").
DESTINATION_MARKERS = ("on", "in", "into", "onto", "next to", "near to", "inside", "at", "to")
FUZZY_MIN_LEN = 4  # shorter words are too easy to mis-correct ("a" -> "at")
FUZZY_CUTOFF = 0.8  # "bottel" -> bottle (0.83), not "nice" -> mice (0.75)

_TABLES: tuple[tuple[str, dict[str, str]], ...] = (
    ("other", {p: "other" for p in L.OTHER_PHRASES}),
    ("intent", L.phrases(L.INTENT_PHRASES)),
    ("intent", L.phrases(L.REQUEST_PHRASES)),
    ("answer", L.phrases(L.ANSWER_PHRASES)),
    ("correction", {p: "correction" for p in L.CORRECTION_PHRASES if p != "no"}),
    ("filler", {p: "filler" for p in (*L.POLITENESS_PHRASES, *L.DISFLUENCY_WORDS)}),
    ("amount", {p: p for p in L.VAGUE_AMOUNTS}),
    ("motion", L.phrases(L.MOTION_PHRASES)),
    ("relation", L.phrases(L.RELATION_PHRASES)),
    ("ordinal_from", L.phrases(L.ORDINAL_FROM_PHRASES)),
    ("ordinal", {w: str(n) for w, n in L.ORDINAL_WORDS.items()}),
    ("spatial", L.phrases(L.SPATIAL_PHRASES)),
    ("spatial", L.phrases(L.SPATIAL_EXTRA_PHRASES)),
    ("place", L.phrases(L.PLACE_PHRASES)),
    (
        "object",
        {
            **{p: L.canonical_label(key) for p, key in L.phrases(L.OBJECT_PHRASES).items()},
            **L.phrases(L.LABEL_PHRASES),
            **{p: lab for p, lab in L.OBJECT_SYNONYMS.items() if p not in L.OBJECT_CATEGORIES},
        },
    ),
    ("color", L.phrases(L.COLOR_PHRASES)),
    ("direction", L.phrases(L.DIRECTION_PHRASES)),
    ("unit", L.phrases(L.UNIT_PHRASES)),
    ("number", {w: w for w in L.NUMBER_WORDS if w not in ("a", "an")}),
)
_DEICTIC = {**{w: "object" for w in L.DEICTIC_OBJECT_WORDS}, **{w: "place" for w in L.DEICTIC_PLACE_WORDS}}
_FILLER = set(L.FILLER_WORDS)
COLOR_WORDS = L.phrases(L.COLOR_PHRASES)
CONTENT_KINDS = (
    "intent",
    "object",
    "color",
    "spatial",
    "motion",
    "direction",
    "deictic_object",
    "place",
    "unit",
    "number",
    "amount",
)


def _phrase_index() -> dict[tuple[str, ...], tuple[str, str]]:
    """phrase tokens -> (kind, canonical). Earlier tables win on identical phrases."""
    index: dict[tuple[str, ...], tuple[str, str]] = {}
    for kind, table in _TABLES:
        for phrase, canonical in table.items():
            index.setdefault(tuple(phrase.split()), (kind, canonical))
    for kind, table in _TABLES:  # plurals of object words: "cups", "wine glasses", "teddy bears"
        if kind == "object":
            for phrase, canonical in table.items():
                if canonical != L.ANY_OBJECT or phrase == "one":
                    index.setdefault(tuple(L.plural(phrase).split()), (kind, canonical))
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
FUZZY_TARGETS = sorted(
    {
        p
        for kind, table in _TABLES
        if kind in ("color", "object", "spatial", "place")
        for p in table
        if " " not in p and p not in _FILLER and len(p) >= 3
    }
)
FUZZY_INTENT_TARGETS = sorted(
    {p[0] for p, (kind, _) in PHRASES.items() if len(p) == 1 and kind == "intent" and len(p[0]) >= 4}
)
FUZZY_INTENT_CUTOFF = 0.85
# ASR sometimes glues a phrase into one word ("pickup", "putdown").
GLUED = {"".join(p): p for p in PHRASES if len(p) > 1}
_NUMBER = re.compile(r"^\d+(\.\d+)?$")


@dataclass(frozen=True)
class Tag:
    kind: str  # intent, answer, spatial, place, object, color, deictic_object, deictic_place, dest, motion …
    value: str  # canonical name (or the deictic word itself)
    index: int  # position of the first token
    words: tuple[str, ...]  # the tokens as heard


RELATION_WORDS = {
    "next_to": "next to",
    "behind": "behind",
    "in_front_of": "in front of",
    "left_of": "left of",
    "right_of": "right of",
    "on": "on",
    "in": "in",
    "under": "under",
    "above": "above",
    "between": "between",
}
ORDINAL_NAMES = {1: "first", 2: "second", 3: "third", 4: "fourth", 5: "fifth", -1: "last", -2: "second last"}


@dataclass(frozen=True)
class Relation:
    """ "next to the bowl": `kind` (common.language.RELATION_PHRASES) and the anchor(s) it relates the head to
    (one phrase, or two for "between the cup and the bowl"; "between the two bottles" is one phrase)."""

    kind: str
    anchors: tuple["ObjectPhrase", ...]

    def describe(self) -> str:
        return f"{RELATION_WORDS[self.kind]} " + " and ".join(f"the {a.describe()}" for a in self.anchors)


@dataclass(frozen=True)
class ObjectPhrase:
    color: str | None = None
    label: str | None = None  # a label, a category of common.language, or "object" (= any); None = not said
    spatial: tuple[str, ...] = ()
    deictic: bool = False  # "this", "that", "it": a gesture (or the dialogue) should say which
    noun: str | None = None  # a noun the language does not know ("pitcher"), singular
    relations: tuple[Relation, ...] = ()  # "next to the bowl", "on the table"
    ordinal: int | None = None  # "the second …" (1-based), -1 "the last …"
    ordinal_from: str | None = None  # counted from: left (default), right, top, bottom, nearest, farthest
    unmatched: tuple[str, ...] = ()  # modifiers nothing can check ("the soap bottle"): said back, never dropped

    @property
    def specific(self) -> bool:
        """True if the words constrain which object (not just "it"/"that one")."""
        return bool(
            self.color or (self.label and self.label != L.ANY_OBJECT) or self.spatial or self.relations or self.ordinal
        )

    @property
    def names_kind(self) -> bool:
        """A kind of thing is named ("the bottle", "the fruit"), not just "one"/"it"."""
        return self.label not in (None, L.ANY_OBJECT)

    def describe(self) -> str:
        noun = self.noun or (self.label if self.label and self.label != L.ANY_OBJECT else "one")
        ordinal = ORDINAL_NAMES.get(self.ordinal or 0, "")
        words = [ordinal, *self.spatial, self.color or "", *self.unmatched, noun]
        if self.ordinal and self.ordinal_from:
            words.append(f"from the {self.ordinal_from}")
        words.extend(r.describe() for r in self.relations)
        return " ".join(w for w in words if w) if self.specific or self.noun else ("that one" if self.deictic else "it")

    @property
    def unknown_nouns(self) -> tuple[str, ...]:
        """Nouns nothing can name, in the phrase and its anchors ("next to the kettle")."""
        own = (self.noun,) if self.noun else ()
        return own + tuple(n for r in self.relations for a in r.anchors for n in a.unknown_nouns)


@dataclass(frozen=True)
class Utterance:
    text: str
    tokens: tuple[str, ...]
    intent: Intent | None = None
    answer: str | None = None  # confirm / deny
    obj: ObjectPhrase = field(default_factory=ObjectPhrase)
    place: str | None = None  # a named place (table, kitchen …)
    deictic_place: str | None = None  # "there" / "here"
    dest_obj: ObjectPhrase | None = None  # "put it on the red box"
    corrections: tuple[tuple[str, str], ...] = ()  # (heard, understood) fuzzy matches
    unknown: tuple[str, ...] = ()  # content words nothing matched
    motion: Motion | None = None  # intent "move" (direction, distance) / "turn" (direction, angle): the wire's Motion
    motion_said: str = ""  # the motion's amount as said ("ten meters", "a bit")
    other: bool = False  # "the other one", "not that one"
    self_corrected: bool = False  # "the red, no, the blue cup"

    @property
    def has_content(self) -> bool:
        return bool(
            self.intent
            or self.answer
            or self.obj.specific
            or self.obj.deictic
            or self.place
            or self.deictic_place
            or self.other
        )

    @property
    def looks_at_something(self) -> bool:
        """A gesture just after the words may complete them: they name an object or a place ("that", "the red one"
        + a point), have words nothing matched, or ask for an action on something not named ("pick up" + a point).
        A motion ("turn left", "go forward one meter"), "come here", a greeting or a bare answer names nothing to
        look at: its decision does not wait for gestures after the utterance."""
        named = self.obj.specific or self.obj.deictic or self.place or self.deictic_place or self.dest_obj
        if named or self.other or self.unknown:
            return True
        return self.intent in L.INTENT_AFFORDANCES  # an intent not listed there acts on no object

    @property
    def deictic(self) -> bool:
        return self.obj.deictic or self.deictic_place is not None


def tokenize(text: str) -> list[str]:
    text = text.lower().replace("°", " degrees ").replace("’", "'").replace("'", " ").replace("-", " ")
    text = re.sub(r"(\d),(\d{3})", r"\1\2", text)  # "1,000"
    tokens: list[str] = []
    for word in re.findall(r"\d+(?:\.\d+)?|[a-z]+", text):
        word = _verb_stem(word)
        tokens.extend(GLUED.get(word, (word,)) if (word,) not in PHRASES else (word,))
    return tokens


def _verb_stem(word: str) -> str:
    """'picking' -> 'pick', 'moving' -> 'move', 'putting' -> 'put' when the stem is a verb of the language
    ("would you mind picking up the cup")."""
    if not word.endswith("ing") or (word,) in PHRASES:
        return word
    for stem in (word[:-3], word[:-3] + "e", word[:-4]):
        hit = PHRASES.get((stem,))
        if hit is not None and hit[0] in ("intent", "motion"):
            return stem
    return word


def word_key(word: str) -> str:
    """A recogniser's word as the parser reads it: Whisper gives ' Cup.' or ' that,'."""
    return word.strip().lower().strip(".,!?;:\"'()")


def singular(word: str) -> str:
    if word.endswith("ies") and len(word) > 4:
        return word[:-3] + "y"
    if word.endswith(("ses", "xes", "ches", "shes")):
        return word[:-2]
    if word.endswith("s") and not word.endswith(("ss", "us", "is", "os")) and len(word) > 3:
        return word[:-1]
    return word


def _fuzzy(token: str) -> str | None:
    if len(token) < FUZZY_MIN_LEN:
        return None
    match = difflib.get_close_matches(
        token, FUZZY_INTENT_TARGETS, n=1, cutoff=FUZZY_INTENT_CUTOFF
    ) or difflib.get_close_matches(token, FUZZY_TARGETS, n=1, cutoff=FUZZY_CUTOFF)
    return match[0] if match else None


def _label_index(labels: tuple[str, ...]) -> dict[tuple[str, ...], tuple[str, str]]:
    """Labels of the objects in view that the language does not know (a user's label file): they are nouns too."""
    index: dict[tuple[str, ...], tuple[str, str]] = {}
    for label in labels:
        label = L.canonical_label(label)
        for phrase in (label, L.plural(label)):
            key = tuple(phrase.split())
            if key and key not in PHRASES:
                index[key] = ("object", label)
    return index


def tag(tokens: list[str], labels: tuple[str, ...] = ()) -> tuple[list[Tag], list[tuple[str, str]], list[str]]:
    """Greedy longest-phrase tagging with a fuzzy fallback for unknown single words. Unknown words are
    tagged `unknown` (and listed) so the reader can tell a noun it does not know."""
    tags: list[Tag] = []
    corrections: list[tuple[str, str]] = []
    unknown: list[str] = []
    extra = _label_index(labels)
    longest = max([MAX_PHRASE, *map(len, extra)])
    toks = list(tokens)
    i = 0
    while i < len(toks):
        for n in range(min(longest, len(toks) - i), 0, -1):
            key = tuple(toks[i : i + n])
            hit = PHRASES.get(key) or extra.get(key)
            if hit is not None:
                tags.append(Tag(hit[0], hit[1], i, key))
                i += n
                break
        else:
            word = toks[i]
            if word in DESTINATION_MARKERS:
                tags.append(Tag("dest", word, i, (word,)))
            elif _NUMBER.match(word):
                tags.append(Tag("number", word, i, (word,)))
            elif word not in _FILLER:
                fixed = _fuzzy(word)
                if fixed is not None:
                    corrections.append((word, fixed))
                    toks[i] = fixed
                    continue  # re-read with the correction (it may start a longer phrase)
                unknown.append(word)
                tags.append(Tag("unknown", word, i, (word,)))
            i += 1
    tags = _person_pronouns(tags)  # "give it to her"
    unknown = [
        w for w in unknown if w not in L.PERSON_PRONOUNS or any(t.kind == "unknown" and t.value == w for t in tags)
    ]
    return tags, corrections, unknown


def _unknown_noun(tags: list[Tag], tokens: tuple[str, ...]) -> tuple[str | None, bool]:
    """The last unknown word in a noun's place: after a determiner, a colour, a size/position word or a known
    object word ("the coffee pot": the head noun is the last word). Returns (noun, replaces_label)."""
    for k in range(len(tags) - 1, -1, -1):
        t = tags[k]
        if t.kind != "unknown":
            continue
        before = tokens[t.index - 1] if t.index > 0 else ""
        prev = tags[k - 1] if k > 0 and tags[k - 1].index + len(tags[k - 1].words) == t.index else None
        if before in L.DETERMINERS or (prev is not None and prev.kind in ("color", "spatial", "deictic_object")):
            return singular(t.value), False
        if prev is not None and prev.kind == "object" and prev.value != L.ANY_OBJECT:
            return " ".join((*prev.words, singular(t.value))), True
    return None, False


def _object_phrase(tags: list[Tag], tokens: tuple[str, ...] = ()) -> ObjectPhrase:
    color = next((t.value for t in tags if t.kind == "color"), None)
    objects = [t for t in tags if t.kind == "object"]
    # The head noun is the last object word ("the computer mouse", "something to eat, some food"); an object
    # word before it that is also a colour is the colour ("the orange cup").
    # A word that is a colour and a label ("orange") followed by a noun ("the orange one", "the orange cup") is
    # the colour.
    as_color = [
        t
        for t in objects
        if " ".join(t.words) in COLOR_WORDS
        and t.value != L.ANY_OBJECT
        and any(x.index > t.index and x.kind in ("object", "unknown") for x in tags)
    ]
    named = [t for t in objects if t.value != L.ANY_OBJECT and t not in as_color]
    label = named[-1].value if named else next((t.value for t in objects if t not in as_color), None)
    if color is None and as_color:
        color = COLOR_WORDS[" ".join(as_color[0].words)]
    spatial = tuple(dict.fromkeys(t.value for t in tags if t.kind == "spatial"))
    deictic = any(t.kind == "deictic_object" for t in tags)
    if label == L.ANY_OBJECT and any(t.kind == "deictic_object" for t in tags):
        label = None  # "that one": "one" is not a class
    noun, replaces = _unknown_noun(tags, tokens) if tokens else (None, False)
    if noun is not None and (replaces or label is None or label == L.ANY_OBJECT):
        label = None
    else:
        noun = None
    return ObjectPhrase(color=color, label=label, spatial=spatial, deictic=deictic, noun=noun)


_NOUN_KINDS = ("object", "unknown")


def _anchor_tags(segment: list[Tag]) -> list[Tag]:
    """A relation's anchor as object tags: a place the detector names ("the table") becomes its label."""
    out = []
    for t in segment:
        if t.kind == "place" and " ".join(t.words) in L.PLACE_AS_OBJECT:
            out.append(Tag("object", L.PLACE_AS_OBJECT[" ".join(t.words)], t.index, t.words))
        elif t.kind != "place":
            out.append(t)
    return out


def _read_object(tags: list[Tag], tokens: tuple[str, ...]) -> ObjectPhrase:
    """The object phrase with its relations ("the bottle next to the bowl"), ordinal ("the second bottle from the
    left") and modifiers nothing checks ("the soap bottle"). The head noun is read from the words before the
    first relation: "the bottle next to the bowl" is a bottle. Words after an anchor's noun ("… next to the sink
    on the left") describe the head again."""
    cuts = [k for k, t in enumerate(tags) if t.kind == "relation"]
    head = list(tags[: cuts[0]] if cuts else tags)
    relations: list[Relation] = []
    spatial_alone: list[str] = []
    for n, k in enumerate(cuts):
        segment = _anchor_tags(list(tags[k + 1 : cuts[n + 1]] if n + 1 < len(cuts) else tags[k + 1 :]))
        kind = tags[k].value
        nouns = [
            j
            for j, t in enumerate(segment)
            if t.kind in _NOUN_KINDS and not (t.kind == "object" and t.value == L.ANY_OBJECT and t.words != ("one",))
        ]
        if not nouns:  # "the chair in front", "the cup behind": a position, no anchor
            if kind in L.RELATION_ALONE:
                spatial_alone.append(L.RELATION_ALONE[kind])
            head.extend(t for t in segment if t.kind != "place")
            continue
        last = nouns[-1]
        anchor_part, after = segment[: last + 1], segment[last + 1 :]
        head.extend(t for t in after if t.kind in ("spatial", "ordinal", "ordinal_from"))
        named = [j for j in nouns if segment[j].kind == "object" and segment[j].value != L.ANY_OBJECT]
        if kind == "between" and len(named) >= 2:  # "between the cup and the bowl"
            parts, start = [], 0
            for j in named:
                parts.append(_object_phrase(anchor_part[start : j + 1], tokens))
                start = j + 1
            anchors = tuple(parts)
        else:
            anchors = (_object_phrase(anchor_part, tokens),)
        relations.append(Relation(kind, anchors))
    if relations:  # "the bottle that is next to the bowl": "that" is not pointing
        head = [
            t
            for t in head
            if t.kind != "deictic_object" or not any(x.kind == "object" and x.index < t.index for x in head)
        ]
    head = [t for t in head if t.kind != "place"]
    phrase = _object_phrase(head, tokens)
    ordinal = next((int(t.value) for t in head if t.kind == "ordinal"), None)
    ordinal_from = next((t.value for t in head if t.kind == "ordinal_from"), None)
    spatial = tuple(dict.fromkeys((*phrase.spatial, *spatial_alone)))
    head_noun = next((t for t in reversed(head) if t.kind == "object" and t.value == phrase.label), None)
    unmatched = tuple(
        t.value
        for t in head
        if t.kind == "unknown" and head_noun is not None and t.index < head_noun.index and phrase.noun is None
    )
    if ordinal is not None and phrase.label is None:
        phrase = replace(phrase, label=L.ANY_OBJECT)
    return replace(
        phrase,
        spatial=spatial,
        relations=tuple(relations),
        ordinal=ordinal,
        ordinal_from=ordinal_from if ordinal is not None else None,
        unmatched=unmatched,
    )


def _person_pronouns(tags: list[Tag]) -> list[Tag]:
    """ "give it to her": "her" with no noun after it is the person; "her cup" keeps it a determiner."""
    out = []
    for k, t in enumerate(tags):
        nxt = tags[k + 1] if k + 1 < len(tags) else None
        if (
            t.kind == "unknown"
            and t.value in L.PERSON_PRONOUNS
            and (nxt is None or nxt.kind not in ("object", "unknown", "color", "spatial"))
        ):
            t = Tag("object", "person", t.index, t.words)
        out.append(t)
    return out


def _merge(before: ObjectPhrase, after: ObjectPhrase) -> ObjectPhrase:
    """A self-correction: what is said after "no" replaces what was said before; what it leaves out
    ("the red cup, no, the blue one") is kept when the correction names no other kind of thing."""
    names_kind = (after.label not in (None, L.ANY_OBJECT)) or after.noun is not None
    if names_kind:
        return after
    moved = bool(after.spatial or after.relations or after.ordinal)  # a new position replaces the old colour too
    return ObjectPhrase(
        color=after.color or (before.color if not moved else None),
        label=before.label,
        spatial=after.spatial or (before.spatial if not moved else ()),
        deictic=after.deictic or before.deictic,
        noun=before.noun,
        relations=after.relations or (before.relations if not moved else ()),
        ordinal=after.ordinal if moved else before.ordinal,
        ordinal_from=after.ordinal_from if moved else before.ordinal_from,
        unmatched=after.unmatched or before.unmatched,
    )


def _is_number(t: Tag) -> bool:
    return t.kind == "number" or (t.kind == "object" and t.words == ("one",))


def _number(tags: list[Tag], k: int, tokens: tuple[str, ...]) -> tuple[float | None, int]:
    """The number starting at tags[k] ("ten", "2.5", "twenty five", "one and a half", "half a", "a couple of"),
    and the index of the tag after it."""
    value: float | None = None
    j = k
    while j < len(tags) and _is_number(tags[j]):
        if j > k and not set(tokens[tags[j - 1].index + 1 : tags[j].index]) <= {"and", "a", "an"}:
            break
        word = tags[j].value if tags[j].kind == "number" else "one"
        if _NUMBER.match(word):
            value = (value or 0.0) + float(word)
        elif word == "hundred":
            value = (value or 1.0) * 100
        else:
            value = (value or 0.0) + L.NUMBER_WORDS[word]
        j += 1
    return value, j


@dataclass
class _MotionSaid:
    """What the words after a motion verb said so far (the last one said wins)."""

    kind: Literal["move", "turn"]
    direction: str | None = None
    distance: float | None = None
    angle: float | None = None
    amount: str = ""  # the amount as said

    def quantity(self, quantity: str, value: float) -> None:
        if quantity == "angle":
            self.angle, self.kind = value, "turn"
        else:
            self.distance = value


def _motion(tags: list[Tag], tokens: tuple[str, ...], verb: Tag) -> tuple[Intent, Motion, str] | None:
    """Direction and amount after a motion verb; the last one said wins ("forward, no, back"). Returns the
    intent ("move" or "turn"), the motion and its amount as said."""
    said = _MotionSaid("turn" if verb.kind == "motion" and verb.value == "turn" else "move")
    if verb.kind == "motion" and verb.words == ("back", "up"):
        said.direction = "back"
    after = [t for t in tags if t.index > verb.index]
    k = 0
    while k < len(after):
        k = _read_motion_word(after, k, tokens, said)
    return _motion_of(said)


def _read_motion_word(after: list[Tag], k: int, tokens: tuple[str, ...], said: _MotionSaid) -> int:
    """Reads the tag at `k` (with the unit after a number) into `said`; the index of the next tag to read."""
    t = after[k]
    if t.kind == "direction" or (t.kind == "spatial" and t.value in L.DIRECTION_PHRASES):
        said.direction = t.value
    elif t.kind == "amount":
        vague = L.VAGUE_AMOUNTS[t.value]
        said.distance, said.angle = (None, vague[1]) if said.kind == "turn" else (vague[0], None)
        said.amount = t.value
    elif _is_number(t):
        value, j = _number(after, k, tokens)
        unit = after[j] if j < len(after) and after[j].kind == "unit" else None
        if value is not None:
            default = ("angle", 1.0) if said.kind == "turn" else ("distance", 1.0)
            quantity, scale = L.UNIT_SCALE[unit.value] if unit else default
            said.quantity(quantity, value * scale)
            last = after[j] if unit else after[j - 1]
            said.amount = " ".join(tokens[t.index : last.index + len(last.words)])  # as said: "one and a half meters"
            return j + (1 if unit else 0)
    elif t.kind == "unit":  # "a meter", "a step": the article is the number
        quantity, scale = L.UNIT_SCALE[t.value]
        said.quantity(quantity, scale)
        said.amount = " ".join(t.words)
    return k + 1


def _motion_of(said: _MotionSaid) -> tuple[Intent, Motion, str] | None:
    direction, amount = said.direction, said.amount
    if said.kind == "turn":
        if direction == "back":
            direction = "around"
        angle = said.angle
        if angle is None:
            angle = L.TURN_AROUND_DEG if direction == "around" else L.TURN_DEFAULT_DEG
        if direction is None and abs(angle - 180.0) < 1e-6:
            direction = "around"
        return "turn", Motion(direction=_wire_direction(direction), angle=round(angle, 3)), amount
    distance = said.distance
    if direction is None and distance is None:
        return None
    if direction == "around":  # "go around" is a turn, not a distance
        return "turn", Motion(direction="around", angle=L.TURN_AROUND_DEG), amount
    return (
        "move",
        Motion(
            direction=_wire_direction(direction or "forward"), distance=None if distance is None else round(distance, 4)
        ),
        amount,
    )


def _wire_direction(direction: str | None) -> MotionDirection | None:
    # a direction tag's value is a key of language.DIRECTION_PHRASES, which are the wire's MotionDirection names
    # (test_fusion_language checks the two lists are equal)
    return cast(MotionDirection | None, direction)


def _split_correction(tags: list[Tag]) -> int | None:
    """The position of the last correction word that follows something said and precedes something else."""
    split = None
    for k, t in enumerate(tags):
        is_marker = t.kind == "correction" or (t.kind == "answer" and t.value == "deny" and t.words == ("no",))
        if not is_marker:
            continue
        said_before = any(x.kind in CONTENT_KINDS for x in tags[:k])
        said_after = any(x.kind in CONTENT_KINDS or x.kind == "unknown" for x in tags[k + 1 :])
        if said_before and said_after:
            split = k
    return split


def stop_requested(tags: list[Tag], tokens: tuple[str, ...]) -> Tag | None:
    """The stop an utterance asks for wherever it is said, or None: a stop word (common.language.STOP_WORDS:
    "please stop", "put it wait no"), "no no no" (STOP_REPEATED_WORD said STOP_REPEATS times in a row), or a
    correction that holds "wait" with nothing after it ("no wait"). "no wait, the blue one" is a correction."""
    for t in tags:
        if t.kind == "intent" and t.value == "stop" and t.words[0] in SAFETY_STOP_WORDS:
            return t
    run = 0
    for i, token in enumerate(tokens):
        run = run + 1 if token == L.STOP_REPEATED_WORD else 0
        if run == L.STOP_REPEATS:
            return Tag("intent", "stop", i - run + 1, tokens[i - run + 1 : i + 1])
    for k, t in enumerate(tags):
        if (
            t.kind == "correction"
            and any(w in SAFETY_STOP_WORDS for w in t.words)
            and not any(x.kind in CONTENT_KINDS or x.kind == "unknown" for x in tags[k + 1 :])
        ):
            return Tag("intent", "stop", t.index, t.words)
    return None


# A word the language does not know, one letter or so from a stop word and starting like it ("stap", "halp",
# "freez"), is taken as that stop word when the recogniser doubted it (its word confidence below
# NEAR_STOP_MAX_CONFIDENCE): a false stop is cheap.
NEAR_STOP_CUTOFF = 0.75  # difflib ratio: "stap" 0.75, "stopp" 0.89; "start" 0.44
NEAR_STOP_MAX_CONFIDENCE = 0.5


def stop_near_miss(words: list[tuple[str, float]]) -> tuple[str, str] | None:
    """(word heard, stop word) for the first doubted near-miss of a stop word in (word, confidence) pairs, or None.
    Words the language knows never count ("want" is not "wait", "step" not "stop", "top" not "stop")."""
    for heard, confidence in words:
        for word in tokenize(heard):
            if (
                confidence >= NEAR_STOP_MAX_CONFIDENCE
                or len(word) < 4
                or word in SAFETY_STOP_WORDS
                or (word,) in PHRASES
                or word in _FILLER
                or word in DESTINATION_MARKERS
            ):
                continue
            # the same onset: a recogniser slips on a vowel or an ending ("stap"), and "what" is not "wait"
            match = difflib.get_close_matches(
                word, [w for w in SAFETY_STOP_WORDS if w[:2] == word[:2]], n=1, cutoff=NEAR_STOP_CUTOFF
            )
            if match:
                return word, match[0]
    return None


def parse(text: str, labels: tuple[str, ...] = ()) -> Utterance:
    """Read `text`. `labels`: labels of the objects in view, so a user's own label ("widget") is a noun."""
    tokens = tuple(tokenize(text))
    tags, corrections, unknown = tag(list(tokens), labels)
    heard_tags = tags
    split = _split_correction(tags)
    before: list[Tag] = []
    if split is not None:
        before, tags = tags[:split], tags[split + 1 :]
        if not any(t.kind in ("intent", "motion") for t in tags):  # "pick up the red, no, the blue cup"
            tags = [t for t in before if t.kind in ("intent", "motion")] + tags
            before = [t for t in before if t.kind not in ("intent", "motion")]
        else:
            before = []
    intents = [t for t in tags if t.kind == "intent"]
    chosen = next((t for t in intents if t.value != "greet"), intents[0] if intents else None)
    intent: Intent | None = as_intent(chosen.value) if chosen else None
    stop = stop_requested(heard_tags, tokens)
    if stop is not None:
        intent, chosen = "stop", stop
    answer_tag = next((t for t in tags if t.kind == "answer"), None)
    other = any(t.kind == "other" for t in tags)
    # Everything after the intent phrase; split object vs destination at the first marker.
    start = chosen.index + len(chosen.words) if chosen else 0
    rest = [t for t in tags if t.index >= start and t.kind not in ("intent", "answer")]
    if intent == "put_down":  # "put <object> on|in|there <destination>"
        split_at = next(
            (k for k, t in enumerate(rest) if t.kind in ("dest", "deictic_place", "place", "relation")), len(rest)
        )
        obj_tags, dest_tags = rest[:split_at], rest[split_at:]
    else:  # the object phrase *is* the destination of go_to / look_at
        obj_tags, dest_tags = [t for t in rest if t.kind not in ("dest", "deictic_place")], rest
    obj = _read_object(obj_tags, tokens)
    if before:
        obj = _merge(_read_object([t for t in before if t.index >= start], tokens), obj)
    first_relation = next((t.index for t in obj_tags if t.kind == "relation"), None)
    anchored = {
        t.index
        for t in obj_tags
        if t.kind == "place"
        and " ".join(t.words) in L.PLACE_AS_OBJECT
        and first_relation is not None
        and t.index > first_relation
        and obj.relations
    }  # "on the table"
    place = next((t.value for t in dest_tags if t.kind == "place" and t.index not in anchored), None)
    deictic_place = next((t.value for t in dest_tags if t.kind == "deictic_place"), None)
    dest_obj = None
    if intent == "put_down":
        after_marker = [t for t in dest_tags if t.kind not in ("dest", "relation")]
        candidate = _object_phrase(after_marker)
        if candidate.specific:
            dest_obj = candidate
    motion = None
    motion_said = ""
    verb = next((t for t in tags if t.kind == "motion"), None)
    if verb is None and chosen is not None and chosen.value == "go_to":
        verb = chosen
    if (
        verb is not None
        and intent in (None, "go_to")
        and not (
            obj.label not in (None, L.ANY_OBJECT) or obj.color or obj.deictic or obj.noun or place or deictic_place
        )
    ):
        moved = _motion(before + tags if before else tags, tokens, verb)
        if moved is not None:
            intent, motion, motion_said = moved
            obj = ObjectPhrase()
    return Utterance(
        text=text,
        tokens=tokens,
        intent=intent,
        answer=answer_tag.value if answer_tag else None,
        obj=obj,
        place=place,
        deictic_place=deictic_place,
        dest_obj=dest_obj,
        corrections=tuple(corrections),
        unknown=tuple(unknown),
        motion=motion,
        motion_said=motion_said,
        other=other,
        self_corrected=split is not None,
    )
