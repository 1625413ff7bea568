"""The robot's command language, defined once.

The speech service generates its recognition grammar from these tables and
fusion's parser reads utterances with them, so a word added here is both
recognised and understood. Every table maps a canonical name to the phrases
that mean it (the canonical name first). Phrases are lower case, words
separated by single spaces.
"""

from __future__ import annotations

# What the robot can be asked to do. Order matters where phrases overlap: the
# parser prefers the longest phrase, so "put down" beats "put".
INTENT_PHRASES: dict[str, tuple[str, ...]] = {
    "pick_up": ("pick up", "pick", "grab", "take", "get", "lift", "collect"),
    "bring": ("bring", "bring me", "give me", "give", "hand me", "fetch", "pass me"),
    "put_down": ("put down", "put", "place", "drop", "set down", "leave"),
    "go_to": ("go to", "go", "move to", "drive to", "navigate to", "head to"),
    "come_here": ("come here", "come", "come to me", "come over here"),
    "stop": ("stop", "halt", "freeze", "stay", "wait"),
    "look_at": ("look at", "look", "watch", "find", "show me", "point at"),
    "follow": ("follow", "follow me"),
    "greet": ("hello", "hi", "hey", "good morning", "good afternoon", "say hello"),
}

# Short answers to a clarification question.
ANSWER_PHRASES: dict[str, tuple[str, ...]] = {
    "confirm": ("yes", "yeah", "yep", "correct", "that is right", "okay", "sure", "exactly"),
    "deny": ("no", "nope", "wrong", "not that", "not that one", "cancel", "never mind"),
}

# Colour words. The keys are the colour names vision publishes in `color`.
COLOR_PHRASES: dict[str, tuple[str, ...]] = {
    "red": ("red", "crimson", "scarlet", "maroon", "cherry"),
    "orange": ("orange", "amber", "tangerine"),
    "yellow": ("yellow", "golden", "gold", "lemon"),
    "green": ("green", "lime", "olive", "emerald"),
    "blue": ("blue", "navy", "azure", "cyan", "turquoise", "teal"),
    "purple": ("purple", "violet", "magenta", "lilac", "pink"),
    "white": ("white", "cream", "ivory"),
    "black": ("black", "dark"),
    "grey": ("grey", "gray", "silver"),
}

# Object classes. Keys are canonical labels; detector labels are mapped onto them by LABEL_ALIASES.
OBJECT_PHRASES: dict[str, tuple[str, ...]] = {
    "cup": ("cup", "mug", "glass", "beaker", "coffee"),
    "bottle": ("bottle", "flask"),
    "ball": ("ball",),
    "box": ("box", "package", "carton", "cube", "block", "brick"),
    "book": ("book", "notebook"),
    "candy": ("candy", "sweet", "sweets", "smartie", "smarties", "candies"),
    "fruit": ("fruit", "apple", "banana", "pear", "lemon fruit"),
    "bowl": ("bowl", "dish"),
    "toy": ("toy", "teddy", "duck"),
    "phone": ("phone", "mobile"),
    "object": ("object", "thing", "item", "one", "stuff"),
}

# Detector label -> canonical class (COCO names and the colour backend's labels).
LABEL_ALIASES: dict[str, str] = {
    "cup": "cup", "wine glass": "cup", "mug": "cup",
    "bottle": "bottle",
    "sports ball": "ball", "ball": "ball",
    "box": "box", "suitcase": "box", "block": "box",
    "book": "book",
    "candy": "candy",
    "apple": "fruit", "banana": "fruit", "orange": "fruit", "fruit": "fruit",
    "bowl": "bowl",
    "teddy bear": "toy", "toy": "toy",
    "cell phone": "phone", "phone": "phone",
    "object": "object",
}

# Spatial and ordinal selectors: canonical name -> phrases.
SPATIAL_PHRASES: dict[str, tuple[str, ...]] = {
    "left": ("left", "leftmost", "on the left", "left one", "left side"),
    "right": ("right", "rightmost", "on the right", "right one", "right side"),
    "middle": ("middle", "center", "centre", "in the middle", "between"),
    "top": ("top", "upper", "at the top"),
    "bottom": ("bottom", "lower", "at the bottom"),
    "nearest": ("nearest", "closest", "near", "close"),
    "farthest": ("farthest", "furthest", "far"),
    "biggest": ("biggest", "largest", "big", "large", "bigger", "larger"),
    "smallest": ("smallest", "tiniest", "small", "little", "smaller", "tiny"),
}

# Words that need a gesture (or the dialogue) to resolve.
DEICTIC_OBJECT_WORDS: tuple[str, ...] = ("this", "that", "these", "those", "it")
DEICTIC_PLACE_WORDS: tuple[str, ...] = ("there", "here")

# Named places for go_to / put_down when no pointing is involved.
PLACE_PHRASES: dict[str, tuple[str, ...]] = {
    "table": ("table", "desk"),
    "shelf": ("shelf",),
    "kitchen": ("kitchen",),
    "door": ("door", "entrance"),
    "basket": ("basket", "bin", "tray"),
    "charger": ("charger", "dock", "charging station"),
}

# Words that carry no meaning for the parser (articles, politeness, prepositions).
FILLER_WORDS: tuple[str, ...] = (
    "the", "a", "an", "please", "robot", "now", "up", "me", "to", "on", "in", "into", "onto", "at", "of",
    "and", "then", "can", "you", "could", "would", "kindly", "for", "over", "with", "one", "ones", "is",
)


def phrases(table: dict[str, tuple[str, ...]]) -> dict[str, str]:
    """Flatten a table into phrase -> canonical name."""
    return {p: canonical for canonical, ps in table.items() for p in ps}


def vocabulary() -> set[str]:
    """Every single word the language uses (for grammars and ASR prompts)."""
    words: set[str] = set(FILLER_WORDS) | set(DEICTIC_OBJECT_WORDS) | set(DEICTIC_PLACE_WORDS)
    for table in (INTENT_PHRASES, ANSWER_PHRASES, COLOR_PHRASES, OBJECT_PHRASES, SPATIAL_PHRASES, PLACE_PHRASES):
        for ps in table.values():
            for p in ps:
                words.update(p.split())
    return words


def canonical_label(detector_label: str) -> str:
    """Map a detector's label to the language's class name (unknown labels map to themselves)."""
    return LABEL_ALIASES.get(detector_label.lower().strip(), detector_label.lower().strip())
