"""The recognition grammar, generated from the one command language in `common.language`.

The grammar is built once as a small tree and rendered twice: as JSGF for pocketsphinx and as a
regular expression over words, which checks any backend's text against the same language. No
vocabulary lives here; this module only gives the language's words their roles in a sentence
(intent, then an object, then a place). Filler words get a role by name when the language has
them (articles, prepositions, particles); whatever filler is left is politeness around a
command.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from typing import Callable, Iterable, Union

from common import language as lang

# Roles of the language's filler words. Each is filtered by what the language defines, so
# removing a word there removes it here too; none of them adds a word.
ARTICLE_ROLE = ("the", "a", "an")
PREPOSITION_ROLE = ("to", "on", "in", "into", "onto", "at", "of", "for", "over", "with")
PARTICLE_ROLE = ("up", "down")  # "pick it up", "put it down"
SELF_ROLE = ("me",)
MODAL_ROLE = ("can", "could", "would")  # "can you ...", said as one politeness unit  # "bring it to me"
NOUN_SUBSTITUTE_ROLE = ("ones",)  # "the red ones" ("one" is an object phrase of the language)
MAX_PREMODIFIERS = 2  # "the small red cup"
# Prior probability that an optional part of a sentence is left out. Tried on the espeak-ng test
# commands, voice en-us+f3 (WER clean / 10 dB): 0.7 -> 0.34/0.51, 0.85 -> 0.33/0.49, 0.95 -> 0.34/0.53.
SKIP_OPTIONAL = 0.85


# -- grammar tree ------------------------------------------------------------
@dataclass(frozen=True)
class Phrase:
    words: tuple[str, ...]


@dataclass(frozen=True)
class Ref:
    rule: str


@dataclass(frozen=True)
class Seq:
    items: tuple["Node", ...]


@dataclass(frozen=True)
class Alt:
    options: tuple["Node", ...]


@dataclass(frozen=True)
class Opt:
    item: "Node"


@dataclass(frozen=True)
class Plus:
    item: "Node"


Node = Union[Phrase, Ref, Seq, Alt, Opt, Plus]


def seq(*items: Node | None) -> Node:
    kept = tuple(i for i in items if i is not None)
    return kept[0] if len(kept) == 1 else Seq(kept)


def alt(*options: Node | None) -> Node | None:
    kept = tuple(o for o in options if o is not None)
    if not kept:
        return None
    return kept[0] if len(kept) == 1 else Alt(kept)


def opt(item: Node | None) -> Node | None:
    return None if item is None else Opt(item)


@dataclass
class Grammar:
    rules: dict[str, Node]  # the first rule is the public one
    skipped: dict[str, str]  # phrase -> why it is not in the grammar
    name: str = "hri"

    @property
    def root(self) -> str:
        return next(iter(self.rules))

    def words(self) -> set[str]:
        found: set[str] = set()

        def walk(node: Node) -> None:
            if isinstance(node, Phrase):
                found.update(node.words)
            elif isinstance(node, (Seq,)):
                for i in node.items:
                    walk(i)
            elif isinstance(node, Alt):
                for o in node.options:
                    walk(o)
            elif isinstance(node, (Opt, Plus)):
                walk(node.item)

        for n in self.rules.values():
            walk(n)
        return found

    # -- renderings ----------------------------------------------------------
    def jsgf(self) -> str:
        lines = ["#JSGF V1.0;", "", f"grammar {self.name};", ""]
        for i, (rule, node) in enumerate(self.rules.items()):
            lines.append(f"{'public ' if i == 0 else ''}<{rule}> = {_jsgf(node, top=True)};")
        return "\n".join(lines) + "\n"

    def fsg(self, skip_optional: float = SKIP_OPTIONAL) -> "WordGraph":
        """The same grammar as a weighted word graph for pocketsphinx's FSG search.

        Every choice splits its probability evenly among its options and an optional part is skipped
        with probability `skip_optional`, so a short, plain sentence is a priori likelier than one
        padded with optional words (measured on clean espeak-ng commands: WER 0.42 -> 0.33 and
        0.49 -> 0.36 in two voices against the same graph with all weights 1, and 5x faster).
        pocketsphinx's own JSGF compiler turns this grammar into ~4,000 states and ~110,000 null
        transitions and decoded 4-10x slower than real time here; compiled directly, alternatives
        share their end states: 149 states and ~1,900 word transitions.
        """
        graph = WordGraph()

        def build(node: Node, src: int, dst: int, p: float) -> None:
            # p: the probability carried by the first transition out of src on this branch
            if isinstance(node, Phrase):
                state = src
                for i, word in enumerate(node.words):
                    nxt = dst if i == len(node.words) - 1 else graph.new_state()
                    graph.words.append((state, nxt, word, p if i == 0 else 1.0))
                    state = nxt
            elif isinstance(node, Ref):
                build(self.rules[node.rule], src, dst, p)
            elif isinstance(node, Seq):
                state = src
                for i, item in enumerate(node.items):
                    nxt = dst if i == len(node.items) - 1 else graph.new_state()
                    build(item, state, nxt, p if i == 0 else 1.0)
                    state = nxt
            elif isinstance(node, Alt):
                for option in node.options:
                    build(option, src, dst, p / len(node.options))
            elif isinstance(node, Opt):
                build(node.item, src, dst, p * (1.0 - skip_optional))
                graph.nulls.append((src, dst, p * skip_optional))
            elif isinstance(node, Plus):
                a, b = graph.new_state(), graph.new_state()  # fresh states: the loop must not leak into siblings
                graph.nulls += [(src, a, p), (b, dst, skip_optional), (b, a, 1.0 - skip_optional)]  # repeats are rare
                build(node.item, a, b, 1.0)
            else:
                raise TypeError(node)

        build(Ref(self.root), graph.start, graph.final, 1.0)
        return graph

    def matcher(self) -> Callable[[str], bool]:
        """A function telling whether a lower-case, space-separated text is a sentence of this grammar."""
        cache: dict[str, str] = {}

        def rx(node: Node) -> str:
            if isinstance(node, Phrase):
                return "".join(re.escape(w) + " " for w in node.words)
            if isinstance(node, Ref):
                if node.rule not in cache:
                    cache[node.rule] = rx(self.rules[node.rule])
                return cache[node.rule]
            if isinstance(node, Seq):
                return "".join(rx(i) for i in node.items)
            if isinstance(node, Alt):
                return "(?:" + "|".join(rx(o) for o in node.options) + ")"
            if isinstance(node, Opt):
                return "(?:" + rx(node.item) + ")?"
            if isinstance(node, Plus):
                return "(?:" + rx(node.item) + ")+"
            raise TypeError(node)

        pattern = re.compile(rx(Ref(self.root)))
        return lambda text: bool(text.split()) and pattern.fullmatch(" ".join(text.split()) + " ") is not None


@dataclass
class WordGraph:
    """A finite-state word graph: state 0 starts, state 1 accepts. Transitions carry probabilities."""

    n_states: int = 2
    words: list[tuple[int, int, str, float]] = field(default_factory=list)  # (from, to, word, probability)
    nulls: list[tuple[int, int, float]] = field(default_factory=list)  # (from, to, probability)
    start: int = 0
    final: int = 1

    def new_state(self) -> int:
        self.n_states += 1
        return self.n_states - 1

    def text(self, name: str = "hri") -> str:
        """Sphinx FSG text format."""
        lines = [
            f"FSG_BEGIN {name}",
            f"NUM_STATES {self.n_states}",
            f"START_STATE {self.start}",
            f"FINAL_STATE {self.final}",
        ]
        lines += [f"TRANSITION {a} {b} {p:.6g} {w}" for a, b, w, p in self.words]
        lines += [f"TRANSITION {a} {b} {p:.6g}" for a, b, p in self.nulls]
        return "\n".join(lines + ["FSG_END"]) + "\n"


def _jsgf(node: Node, top: bool = False) -> str:
    if isinstance(node, Phrase):
        return " ".join(node.words)
    if isinstance(node, Ref):
        return f"<{node.rule}>"
    if isinstance(node, Seq):
        return " ".join(_jsgf(i) for i in node.items)
    if isinstance(node, Alt):
        body = " | ".join(_jsgf(o) for o in node.options)
        return body if top else f"( {body} )"
    if isinstance(node, Opt):
        return f"[ {_jsgf(node.item, top=True)} ]"
    if isinstance(node, Plus):
        return f"( {_jsgf(node.item, top=True)} )+"
    raise TypeError(node)


# -- building ------------------------------------------------------------------
def build_grammar(known: Callable[[str], bool] = lambda word: True) -> Grammar:
    """The command grammar. `known(word)` says whether the recogniser can say a word; phrases with
    other words are left out and listed in `Grammar.skipped`."""
    skipped: dict[str, str] = {}
    fillers = set(lang.FILLER_WORDS)

    def phrases(items: Iterable[str]) -> Node | None:
        kept: list[Node] = []
        for p in dict.fromkeys(items):  # de-duplicate, keep order
            words = tuple(p.split())
            unknown = [w for w in words if not known(w)]
            if unknown:
                skipped[p] = f"not in the pronunciation dictionary: {', '.join(unknown)}"
                continue
            kept.append(Phrase(words))
        return alt(*kept)

    def table(t: dict[str, tuple[str, ...]], single_word: bool = False, multi_word: bool = False) -> Node | None:
        return phrases(
            p for ps in t.values() for p in ps if not (single_word and " " in p) and not (multi_word and " " not in p)
        )

    def role(words: Iterable[str]) -> Node | None:
        return phrases(w for w in words if w in fillers or w in lang.vocabulary())

    roles = set(
        ARTICLE_ROLE + PREPOSITION_ROLE + PARTICLE_ROLE + SELF_ROLE + NOUN_SUBSTITUTE_ROLE + MODAL_ROLE + ("you",)
    )
    polite_words = [w for w in lang.FILLER_WORDS if w not in roles and w not in _object_words()]

    rules: dict[str, Node | None] = {}
    rules["utterance"] = None  # placeholder: the public rule goes first
    rules["polite"] = phrases(polite_words)
    rules["intent"] = table(lang.INTENT_PHRASES)
    rules["answer"] = table(lang.ANSWER_PHRASES)
    rules["color"] = table(lang.COLOR_PHRASES)
    rules["object"] = alt(table(lang.OBJECT_PHRASES), role(NOUN_SUBSTITUTE_ROLE))
    rules["spatial_word"] = table(lang.SPATIAL_PHRASES, single_word=True)
    rules["spatial_phrase"] = table(lang.SPATIAL_PHRASES, multi_word=True)
    rules["deictic"] = phrases(lang.DEICTIC_OBJECT_WORDS)
    rules["here_there"] = phrases(lang.DEICTIC_PLACE_WORDS)
    rules["place"] = table(lang.PLACE_PHRASES)
    rules["article"] = role(ARTICLE_ROLE)
    rules["preposition"] = role(PREPOSITION_ROLE)
    rules["particle"] = role(PARTICLE_ROLE)
    rules["self"] = role(SELF_ROLE)

    def r(name: str) -> Node | None:
        return Ref(name) if rules.get(name) is not None else None

    modifier = alt(r("color"), r("spatial_word"))
    rules["modifier"] = modifier
    premods = seq(r("modifier"), *[opt(r("modifier"))] * (MAX_PREMODIFIERS - 1)) if modifier else None
    # "that", "that cup", "those red ones", "the red cup", "the red one", "the one on the left"
    rules["noun_phrase"] = seq(
        alt(
            seq(r("deictic"), opt(premods), opt(r("object"))),
            seq(opt(r("article")), alt(seq(premods, opt(r("object"))) if premods else None, r("object"))),
        ),
        opt(r("spatial_phrase")),
    )
    # "on the table", "to the kitchen", "there", "to me", "into the red box"
    rules["place_phrase"] = alt(
        seq(
            r("preposition"),
            alt(r("here_there"), r("self"), seq(opt(r("article")), opt(r("modifier")), r("place")), r("noun_phrase")),
        ),
        r("here_there"),
    )
    rules["command"] = seq(r("intent"), opt(seq(r("noun_phrase"), opt(r("particle")))), opt(r("place_phrase")))
    # "pick up the cup", "yes", "no not that one", "the red one" (an answer to "which one?")
    rules["body"] = alt(r("command"), seq(r("answer"), opt(r("answer")), opt(r("noun_phrase"))), r("noun_phrase"))
    # one word of politeness around a command: "please stop", "robot come here", "can you pick that up"
    modal_you = (
        seq(alt(*(Phrase((w,)) for w in MODAL_ROLE if w in fillers)), Phrase(("you",))) if "you" in fillers else None
    )
    rules["polite"] = alt(rules["polite"], modal_you)
    rules["utterance"] = seq(opt(r("polite")), opt(r("polite")), r("body"), opt(r("polite")))
    return Grammar({k: v for k, v in rules.items() if v is not None}, skipped)


def _object_words() -> set[str]:
    return {p for ps in lang.OBJECT_PHRASES.values() for p in ps}


_WORD = re.compile(r"\d+(?:\.\d+)?|[a-z]+(?:'[a-z]+)?")


def normalise_words(text: str) -> list[str]:
    """Lower-case words and numbers, punctuation dropped ("Go 2.5 meters!" -> go, 2.5, meters; "1,000" -> 1000).
    Apostrophes inside words stay; digits stay: fusion's parser reads them."""
    return _WORD.findall(text.lower().replace(",", ""))


def normalise(text: str) -> str:
    """The words of `normalise_words` as one string, as fusion's parser reads them ("Pick up the cup!" ->
    "pick up the cup")."""
    return " ".join(normalise_words(text))
