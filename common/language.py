"""The robot's command language, defined once.

The speech service generates its recognition grammar from these tables and
fusion's parser reads utterances with them, so a word added here is both
recognised and understood. Every table maps a canonical name to the phrases
that mean it (the canonical name first). Phrases are lower case, words
separated by single spaces.
"""

from __future__ import annotations

from typing import Literal

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

# -- affordances: what each action can be done to (issue #31), declared once beside the action words ---------------
# "graspable": a thing a household robot's arm can lift (not a person, an animal, furniture or an appliance, by the
# detector's class; with depth, nothing measured wider or taller than GRASP_MAX_EXTENT_M); "person": a person (give
# it to her, follow him); "anything": anything but the commanding person. An intent not listed acts on no object.
Affordance = Literal["graspable", "person", "anything"]
INTENT_AFFORDANCES: dict[str, Affordance] = {
    "pick_up": "graspable",
    "bring": "graspable",  # "give it to her": the person is the recipient (`affordance`)
    "put_down": "graspable",
    "go_to": "anything",
    "look_at": "anything",  # also "point at"
    "follow": "person",
}
# The detector's classes (COCO) no robot arm lifts, by kind (the kind names the reason in a refusal: "I can't pick up a
# couch: I don't lift furniture."): people and animals (living beings are never "picked up"), vehicles, furniture,
# appliances, fixtures, big sports gear. Everything else is graspable by class, then limited by size. The default
# robot profile (common/robot.py, docs/robot.md); a profile file may name its own.
NEVER_GRASPED: dict[str, tuple[str, ...]] = {
    "living beings": ("person", "bird", "cat", "dog", "horse", "sheep", "cow", "elephant", "bear", "zebra", "giraffe"),
    "vehicles": ("bicycle", "car", "motorcycle", "airplane", "bus", "train", "truck", "boat"),
    "fixtures": ("traffic light", "fire hydrant", "stop sign", "parking meter"),
    "furniture": ("bench", "chair", "couch", "bed", "dining table", "toilet", "sink"),
    "appliances": ("tv", "microwave", "oven", "refrigerator"),
    "big sports gear": ("surfboard", "skis", "snowboard"),
}
NOT_GRASPABLE: frozenset[str] = frozenset(label for labels in NEVER_GRASPED.values() for label in labels)
# The largest visible size (width or height, metres; depth's own spread is a surface's, not the object's) of a
# graspable object: about what one arm with a parallel gripper handles (a laptop 0.35 m, a backpack 0.5 m); a
# suitcase or a floor lamp measured over it is not picked up.
GRASP_MAX_EXTENT_M = 0.6


def affordance(intent: str | None, said_label: str | None) -> Affordance | None:
    """What `intent` can be done to when the words name `said_label`: "give it to her" / "bring him" (bring with a
    person named) hands something to that person; "look at the man" looks at a person. None: no object at all."""
    if intent is None:
        return None
    kind = INTENT_AFFORDANCES.get(intent)
    if said_label == "person" and kind is not None and intent in ("bring", "look_at"):
        return "person"
    return kind


def graspable_class(label: str) -> bool:
    return label not in NOT_GRASPABLE


# -- safety: stop words and the words said alone ---------------------------------------------------
# Any of these anywhere in an utterance stops the robot at once (a false stop is cheap, a missed one is not).
# "stay" is a stop intent too, but only when it is the command ("stay there"), not wherever it appears.
STOP_WORDS: tuple[str, ...] = ("stop", "halt", "freeze", "wait")
# "no no no": this word said at least STOP_REPEATS times in a row is a stop too ("no" once is an answer).
STOP_REPEATED_WORD = "no"
STOP_REPEATS = 3
# Words people say alone to a machine besides the language's one-word intents, answers and directions:
# raise / lower, switch on / off (the classic command-word set of Speech Commands). Heard as commands when
# said alone (speech's short-utterance decode); fusion gives them no meaning yet.
ONE_WORD_EXTRAS: tuple[str, ...] = ("up", "down", "on", "off")


def one_word_commands() -> tuple[str, ...]:
    """The words a person says alone as a command or an answer: every one-word phrase of the intents (stop
    words included), the answers and the directions, then ONE_WORD_EXTRAS. The speech service favours these
    when an utterance of about a second is one word."""
    words: list[str] = []
    for table in (INTENT_PHRASES, ANSWER_PHRASES, DIRECTION_PHRASES):
        words.extend(p for ps in table.values() for p in ps if " " not in p and p not in words)
    words.extend(w for w in ONE_WORD_EXTRAS if w not in words)
    return tuple(words)


# Requests that name no verb ("I'd like the banana"): an intent for the parser only. Kept out of INTENT_PHRASES,
# which the closed speech grammar reads, so that grammar (and its measured accuracy) stays as it was.
REQUEST_PHRASES: dict[str, tuple[str, ...]] = {
    "bring": (
        "i want",
        "i d like",
        "i would like",
        "i need",
        "can i have",
        "could i have",
        "may i have",
        "can i get",
        "could i get",
        "i ll have",
        "i ll take",
    ),
}

# Short answers to a clarification question.
ANSWER_PHRASES: dict[str, tuple[str, ...]] = {
    "confirm": ("yes", "yeah", "yep", "correct", "that is right", "okay", "sure", "exactly"),
    "deny": ("no", "nope", "wrong", "not that", "not that one", "cancel", "never mind"),
}

# Colour words. Each key is a colour term fusion matches by similarity (services/fusion/color.py); the first
# eleven are the basic colour names (Berlin & Kay) vision publishes in `color` and `colors` (docs/vision.md).
BASIC_COLORS: tuple[str, ...] = (
    "red",
    "orange",
    "yellow",
    "green",
    "blue",
    "purple",
    "pink",
    "brown",
    "white",
    "grey",
    "black",
)
_COLOR_TERMS: dict[str, tuple[str, ...]] = {
    "red": ("red", "scarlet", "cherry"),
    "orange": ("orange", "tangerine", "amber"),
    "yellow": ("yellow", "lemon"),
    "green": ("green", "emerald"),
    "blue": ("blue", "azure", "royal blue"),
    "purple": ("purple", "violet"),
    "pink": ("pink", "rose", "salmon"),
    "brown": ("brown", "chocolate", "wooden", "wood"),
    "white": ("white", "ivory", "off white", "snow white"),
    "grey": ("grey", "gray"),
    "black": ("black", "jet black"),
    "crimson": ("crimson", "ruby"),
    "maroon": ("maroon", "burgundy", "wine red", "claret"),
    "navy": ("navy", "navy blue", "midnight blue"),
    "turquoise": ("turquoise", "cyan", "aqua", "aquamarine"),
    "teal": ("teal", "petrol"),
    "beige": ("beige", "tan", "khaki", "sand", "camel"),
    "cream": ("cream", "eggshell"),
    "gold": ("gold", "golden", "mustard"),
    "silver": ("silver", "silvery", "metallic", "chrome", "steel"),
    "olive": ("olive", "olive green"),
    "lime": ("lime", "lime green"),
    "magenta": ("magenta", "fuchsia", "hot pink"),
    "lilac": ("lilac", "lavender", "mauve"),
    "dark": ("dark", "darker"),  # lightness alone: "the dark one"
    "light": ("light", "lighter", "pale", "paler", "bright", "brighter"),  # "the light one"
}
# What each term looks like: CIELAB (D65) prototypes of typical objects of that colour, from sRGB exemplars
# (red: 200,30,35 and 150,25,30; brown: 120,75,40 / 160,115,75 / 80,50,30; …: docs/vision.md lists them all).
# Several prototypes span a wide category (light and dark greys, browns); a term matches its nearest one.
COLOR_PROTOTYPES: dict[str, tuple[tuple[float, float, float], ...]] = {
    "red": ((43, 63, 43), (32, 50, 31), (35, 56, 23)),
    "orange": ((63, 39, 64), (54, 36, 50)),
    "yellow": ((84, -5, 79), (79, -2, 60)),
    "green": ((55, -50, 38), (53, -32, 37), (34, -29, 18)),
    "blue": ((40, 20, -57), (27, 15, -43), (50, 7, -47), (65, -18, -23)),
    "purple": ((33, 57, -48), (40, 49, -39)),
    "pink": ((72, 37, 1), (62, 52, -5)),
    "brown": ((36, 15, 28), (52, 13, 29), (24, 11, 18)),
    "white": ((97, 0, 0),),
    "grey": ((54, 0, 0), (71, 0, 0), (38, 0, 0)),
    "black": ((9, 0, 0),),
    "crimson": ((35, 56, 23),),
    "maroon": ((24, 38, 16),),
    "navy": ((16, 16, -34),),
    "turquoise": ((70, -36, -11),),
    "teal": ((45, -28, -8),),
    "beige": ((83, 2, 20), (75, 5, 24)),
    "cream": ((93, -1, 16),),
    "gold": ((71, 3, 63),),
    "silver": ((77, 1, -3),),
    "olive": ((49, -11, 42),),
    "lime": ((78, -38, 68),),
    "magenta": ((47, 71, -27),),
    "lilac": ((70, 22, -26),),
    "dark": ((15, 0, 0),),  # matched on lightness only (common.color.LIGHTNESS_ONLY)
    "light": ((90, 0, 0),),
}
# Lightness modifiers: "light blue", "pale green", "dark red", "deep purple" are terms of their own, made
# from the base term's prototypes (common.color.modified).
COLOR_MODIFIERS: dict[str, tuple[str, ...]] = {"light": ("light", "pale"), "dark": ("dark", "deep")}
MODIFIABLE_COLORS: tuple[str, ...] = (
    "red",
    "orange",
    "yellow",
    "green",
    "blue",
    "purple",
    "pink",
    "brown",
    "grey",
    "turquoise",
)
VIVID_WORDS: tuple[str, ...] = ("bright", "vivid")  # "bright red" is red: saturation, which real light varies
COLOR_PHRASES: dict[str, tuple[str, ...]] = {
    **{
        term: ps + (tuple(f"{w} {ps[0]}" for w in VIVID_WORDS) if term in MODIFIABLE_COLORS else ())
        for term, ps in _COLOR_TERMS.items()
    },
    **{
        f"{mod} {base}": tuple(f"{word} {p}" for word in words for p in _COLOR_TERMS[base][:2])
        for mod, words in COLOR_MODIFIERS.items()
        for base in MODIFIABLE_COLORS
    },
}
assert set(COLOR_PROTOTYPES) == set(_COLOR_TERMS) and set(BASIC_COLORS) <= set(COLOR_PROTOTYPES)

# The detector's label set: the 80 COCO classes, in the model's class-index order (YOLOX, SSD, YOLOv5 …
# all use it). Vision backends that run a COCO model import this list; everything here names them.
COCO_LABELS: tuple[str, ...] = (
    "person",
    "bicycle",
    "car",
    "motorcycle",
    "airplane",
    "bus",
    "train",
    "truck",
    "boat",
    "traffic light",
    "fire hydrant",
    "stop sign",
    "parking meter",
    "bench",
    "bird",
    "cat",
    "dog",
    "horse",
    "sheep",
    "cow",
    "elephant",
    "bear",
    "zebra",
    "giraffe",
    "backpack",
    "umbrella",
    "handbag",
    "tie",
    "suitcase",
    "frisbee",
    "skis",
    "snowboard",
    "sports ball",
    "kite",
    "baseball bat",
    "baseball glove",
    "skateboard",
    "surfboard",
    "tennis racket",
    "bottle",
    "wine glass",
    "cup",
    "fork",
    "knife",
    "spoon",
    "bowl",
    "banana",
    "apple",
    "sandwich",
    "orange",
    "broccoli",
    "carrot",
    "hot dog",
    "pizza",
    "donut",
    "cake",
    "chair",
    "couch",
    "potted plant",
    "bed",
    "dining table",
    "toilet",
    "tv",
    "laptop",
    "mouse",
    "remote",
    "keyboard",
    "cell phone",
    "microwave",
    "oven",
    "toaster",
    "sink",
    "refrigerator",
    "book",
    "clock",
    "vase",
    "scissors",
    "teddy bear",
    "hair drier",
    "toothbrush",
)

# Labels of the colour backend and of the demo scenes that are not COCO classes.
EXTRA_LABELS: tuple[str, ...] = ("candy", "box", "block")

# Other words people use for a label: word -> the label it names (one label; a word that may mean
# several labels is a category below). "glass" is a category (wine glass or cup), "mug" is a cup.
OBJECT_SYNONYMS: dict[str, str] = {
    "mug": "cup",
    "beaker": "cup",
    "coffee": "cup",
    "tea": "cup",
    "coffee cup": "cup",
    "coffee mug": "cup",
    "flask": "bottle",
    "water bottle": "bottle",
    "ball": "sports ball",
    "football": "sports ball",
    "soccer ball": "sports ball",
    "tennis ball": "sports ball",
    "phone": "cell phone",
    "mobile": "cell phone",
    "mobile phone": "cell phone",
    "smartphone": "cell phone",
    "cellphone": "cell phone",
    "teddy": "teddy bear",
    "stuffed animal": "teddy bear",
    "plush": "teddy bear",
    "television": "tv",
    "tv set": "tv",
    "monitor": "tv",
    "screen": "tv",
    "computer": "laptop",
    "notebook computer": "laptop",
    "sofa": "couch",
    "plant": "potted plant",
    "flower pot": "potted plant",
    "fridge": "refrigerator",
    "doughnut": "donut",
    "remote control": "remote",
    "controller": "remote",
    "hairdryer": "hair drier",
    "hair dryer": "hair drier",
    "bike": "bicycle",
    "motorbike": "motorcycle",
    "plane": "airplane",
    "puppy": "dog",
    "kitten": "cat",
    "bag": "handbag",
    "purse": "handbag",
    "rucksack": "backpack",
    "racket": "tennis racket",
    "bat": "baseball bat",
    "glove": "baseball glove",
    "dish": "bowl",
    "package": "box",
    "carton": "box",
    "cube": "box",
    "brick": "box",
    "parcel": "box",
    "sweet": "candy",
    "smartie": "candy",
    "smarties": "candy",
    "candies": "candy",
    "sweets": "candy",
    "stool": "chair",
    "armchair": "chair",
    "arm chair": "chair",
    "office chair": "chair",
    "rocking chair": "chair",
    "tumbler": "cup",
    "teacup": "cup",
    "coffee glass": "cup",
    "settee": "couch",
    "loveseat": "couch",
    "love seat": "couch",
    "sectional": "couch",
    "stove": "oven",
    "range": "oven",
    "cooker": "oven",
    "cooktop": "oven",
    "hob": "oven",
    "basin": "sink",
    "washbasin": "sink",
    "wash basin": "sink",
    "microwave oven": "microwave",
    "kitchen table": "dining table",
    "coffee table": "dining table",
    "houseplant": "potted plant",
    "house plant": "potted plant",
    "pot plant": "potted plant",
    "telly": "tv",
    "computer screen": "tv",
    "laptop computer": "laptop",
    "him": "person",
    "gentleman": "person",
    "human": "person",
    "man": "person",
    "woman": "person",
    "guy": "person",
    "lady": "person",
    "boy": "person",
    "girl": "person",
    "child": "person",
    "kid": "person",
    "someone": "person",
    "somebody": "person",
    "people": "person",
    "men": "person",
    "women": "person",
    "children": "person",
    "kids": "person",
}

# Words for a kind of thing: word -> the labels it covers. A label itself is always more specific than
# a category that contains it: "the banana" is the banana even with an apple beside it.
OBJECT_CATEGORIES: dict[str, tuple[str, ...]] = {
    "fruit": ("apple", "banana", "orange", "fruit"),
    "drink": ("bottle", "cup", "wine glass"),
    "glass": ("wine glass", "cup"),
    "food": (
        "banana",
        "apple",
        "sandwich",
        "orange",
        "broccoli",
        "carrot",
        "hot dog",
        "pizza",
        "donut",
        "cake",
        "candy",
        "fruit",
    ),
    "snack": ("banana", "apple", "orange", "sandwich", "donut", "cake", "candy"),
    "vegetable": ("broccoli", "carrot"),
    "cutlery": ("fork", "knife", "spoon"),
    "utensil": ("fork", "knife", "spoon"),
    "container": ("bottle", "cup", "bowl", "vase", "box", "wine glass"),
    "toy": ("teddy bear", "sports ball", "kite", "frisbee", "toy", "block"),
    "animal": ("bird", "cat", "dog", "horse", "sheep", "cow", "elephant", "bear", "zebra", "giraffe"),
    "pet": ("cat", "dog", "bird"),
    "vehicle": ("bicycle", "car", "motorcycle", "airplane", "bus", "train", "truck", "boat"),
    "furniture": ("chair", "couch", "bed", "dining table", "bench"),
    "seat": ("chair", "couch", "bench"),
    "flower": ("potted plant", "vase"),  # cut flowers stand in a vase; the detector boxes either
    "greenery": ("potted plant", "vase"),
    "electronics": ("tv", "laptop", "mouse", "remote", "keyboard", "cell phone"),
    "device": ("tv", "laptop", "mouse", "remote", "keyboard", "cell phone"),
    "bag": ("handbag", "backpack", "suitcase"),
    "luggage": ("suitcase", "backpack", "handbag"),
}
ANY_OBJECT = "object"  # the category of "thing", "object", "one": anything
ANY_OBJECT_WORDS: tuple[str, ...] = ("object", "thing", "item", "one", "stuff", "something")

# Every object word fusion understands: label -> the phrases that name it (the label first), then the
# categories (-> their word), then "object" (anything). Built from the tables above; the parser adds plurals
# ("cups", "wine glasses").
LABEL_PHRASES: dict[str, tuple[str, ...]] = {
    label: (label, *[w for w, lab in OBJECT_SYNONYMS.items() if lab == label and w not in OBJECT_CATEGORIES])
    for label in (*COCO_LABELS, *EXTRA_LABELS)
    if label not in OBJECT_CATEGORIES
}
LABEL_PHRASES.update({category: (category,) for category in OBJECT_CATEGORIES})
LABEL_PHRASES[ANY_OBJECT] = ANY_OBJECT_WORDS

# The object words of the closed recognition grammar (pocketsphinx, `--commands`): a compact table-top set,
# kept small because every alternative costs a grammar-constrained recogniser accuracy (a grammar with all of
# LABEL_PHRASES measured WER 0.65 instead of 0.51 on the espeak-ng test voice). The parser understands every
# phrase here too (a key is read through canonical_label: "phone" -> cell phone, "ball" -> sports ball).
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


# Detector label -> the language's label: other spellings and synonyms a detector or a user's label file
# may use ("mug" -> cup, "phone" -> cell phone). Labels not listed are their own name.
LABEL_ALIASES: dict[str, str] = {w: lab for w, lab in OBJECT_SYNONYMS.items() if w not in OBJECT_CATEGORIES}

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

# Relations between objects: canonical name (services/fusion/relations.py) -> phrases. Followed by an object
# ("the bottle next to the bowl") the phrase relates the head noun to that anchor; said alone ("the chair in
# front") it is the spatial word of RELATION_ALONE.
RELATION_PHRASES: dict[str, tuple[str, ...]] = {
    "next_to": (
        "next to",
        "beside",
        "besides",
        "by",
        "near",
        "near to",
        "close to",
        "nearby",
        "alongside",
        "by the side of",
        "at the side of",
        "right next to",
        "right by",
        "just by",
    ),
    "behind": ("behind", "in back of", "at the back of", "further back than"),
    "in_front_of": ("in front of", "in front", "at the front of"),
    "left_of": ("left of", "to the left of", "on the left of", "on the left side of", "left from"),
    "right_of": ("right of", "to the right of", "on the right of", "on the right side of", "right from"),
    "on": ("on", "on top of", "onto", "upon", "sitting on", "standing on", "lying on"),
    "in": ("in", "inside", "inside of", "within", "in the middle of"),
    "under": ("under", "underneath", "below", "beneath"),
    "above": ("above",),
    "between": ("between", "in between"),
}
RELATION_ALONE: dict[str, str] = {
    "next_to": "nearest",
    "behind": "farthest",
    "in_front_of": "nearest",
    "left_of": "left",
    "right_of": "right",
    "between": "middle",
    "under": "bottom",
    "above": "top",
}
# Ordinals: "the second bottle from the left", "the last one". Counted from the left unless said otherwise.
ORDINAL_WORDS: dict[str, int] = {
    "first": 1,
    "second": 2,
    "third": 3,
    "fourth": 4,
    "fifth": 5,
    "last": -1,
    "second last": -2,
    "second to last": -2,
    "next to last": -2,
}
ORDINAL_FROM_PHRASES: dict[str, tuple[str, ...]] = {
    "left": ("from the left", "from left", "counting from the left"),
    "right": ("from the right", "from right", "counting from the right"),
    "top": ("from the top", "from top"),
    "bottom": ("from the bottom", "from bottom"),
    "nearest": ("from the front", "from me"),
    "farthest": ("from the back",),
}
# Place words that are also objects the detector names, when they are a relation's anchor ("the cup on the table").
PLACE_AS_OBJECT: dict[str, str] = {"table": "dining table"}
# Pronouns for a person when nothing follows them ("give it to her"); "her cup" keeps "her" a determiner.
PERSON_PRONOUNS: tuple[str, ...] = ("her", "him", "them")

# More spatial phrases for the parser only (like REQUEST_PHRASES, kept out of the closed speech grammar, whose
# measured accuracy is for SPATIAL_PHRASES as they are). "In front" / "behind" with no object after them are in
# RELATION_ALONE.
SPATIAL_EXTRA_PHRASES: dict[str, tuple[str, ...]] = {
    "left": ("far left", "on the far left", "furthest left"),
    "right": ("far right", "on the far right", "furthest right"),
    "nearest": ("front", "at the front", "in the front", "frontmost", "in the foreground"),
    "farthest": ("at the back", "in the back", "rearmost", "in the background"),
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
    "the",
    "a",
    "an",
    "please",
    "robot",
    "now",
    "up",
    "me",
    "to",
    "on",
    "in",
    "into",
    "onto",
    "at",
    "of",
    "and",
    "then",
    "can",
    "you",
    "could",
    "would",
    "kindly",
    "for",
    "over",
    "with",
    "one",
    "ones",
    "is",
)


# -- motions ----------------------------------------------------------------------------------
# Verbs that move the robot itself ("go forward", "back up") and turn it ("turn left"). A motion verb
# with a direction or an amount and no object or place is a motion, not a `go_to`.
MOTION_PHRASES: dict[str, tuple[str, ...]] = {
    "move": ("move", "go", "drive", "walk", "step", "roll", "back up", "head", "come"),
    "turn": ("turn", "rotate", "spin", "turn yourself"),
}
DIRECTION_PHRASES: dict[str, tuple[str, ...]] = {
    "forward": ("forward", "forwards", "ahead", "straight", "straight ahead", "onward", "onwards"),
    "back": ("back", "backward", "backwards", "reverse", "back up"),
    "left": ("left", "to the left", "leftwards"),
    "right": ("right", "to the right", "rightwards"),
    "around": ("around", "round", "about"),
}
# Units of an amount -> (quantity, factor to metres or degrees).
UNIT_PHRASES: dict[str, tuple[str, ...]] = {
    "metre": ("meter", "meters", "metre", "metres", "m"),
    "centimetre": ("centimeter", "centimeters", "centimetre", "centimetres", "cm"),
    "millimetre": ("millimeter", "millimeters", "millimetre", "millimetres", "mm"),
    "foot": ("foot", "feet", "ft"),
    "inch": ("inch", "inches"),
    "step": ("step", "steps", "pace", "paces"),
    "degree": ("degree", "degrees", "deg"),
}
STEP_M = 0.5  # one of the robot's "steps", in metres (documented in docs/fusion.md)
UNIT_SCALE: dict[str, tuple[str, float]] = {
    "metre": ("distance", 1.0),
    "centimetre": ("distance", 0.01),
    "millimetre": ("distance", 0.001),
    "foot": ("distance", 0.3048),
    "inch": ("distance", 0.0254),
    "step": ("distance", STEP_M),
    "degree": ("angle", 1.0),
}
# Amounts without a number: (distance in metres, angle in degrees).
VAGUE_AMOUNTS: dict[str, tuple[float, float]] = {
    "a bit": (0.25, 15.0),
    "a little": (0.25, 15.0),
    "a little bit": (0.25, 15.0),
    "slightly": (0.25, 15.0),
    "a tiny bit": (0.1, 5.0),
    "a lot": (2.0, 90.0),
}
TURN_DEFAULT_DEG = 90.0  # "turn left" without an amount
TURN_AROUND_DEG = 180.0
NUMBER_WORDS: dict[str, float] = {
    "zero": 0,
    "one": 1,
    "two": 2,
    "three": 3,
    "four": 4,
    "five": 5,
    "six": 6,
    "seven": 7,
    "eight": 8,
    "nine": 9,
    "ten": 10,
    "eleven": 11,
    "twelve": 12,
    "thirteen": 13,
    "fourteen": 14,
    "fifteen": 15,
    "sixteen": 16,
    "seventeen": 17,
    "eighteen": 18,
    "nineteen": 19,
    "twenty": 20,
    "thirty": 30,
    "forty": 40,
    "fifty": 50,
    "sixty": 60,
    "seventy": 70,
    "eighty": 80,
    "ninety": 90,
    "hundred": 100,
    "half": 0.5,
    "couple": 2,
    "few": 3,
    "a": 1,
    "an": 1,
    "single": 1,
    "quarter": 0.25,
}

# -- dialogue -----------------------------------------------------------------------------------
# "The other one": the candidate that was not chosen (or not proposed).
OTHER_PHRASES: tuple[str, ...] = (
    "other",
    "the other",
    "the other one",
    "another",
    "another one",
    "a different one",
    "different one",
    "the other way",
    "not that one",
    "not this one",
    "not that",
    "not this",
    "wrong one",
    "the wrong one",
)
# Words that take back what was just said: "the red, no, the blue cup". Only after something was said.
CORRECTION_PHRASES: tuple[str, ...] = (
    "no",
    "sorry",
    "i mean",
    "i meant",
    "actually",
    "rather",
    "or rather",
    "make that",
    "no wait",
    "wait no",
    "oops",
    "i mean the",
    "correction",
)

# Speech that carries no meaning: hesitations, politeness and softeners real people add ("uh, could you
# please hand me the cup for me, thanks"). Kept apart from FILLER_WORDS, which the speech grammar gives roles.
DISFLUENCY_WORDS: tuple[str, ...] = (
    "uh",
    "um",
    "umm",
    "uhm",
    "uhh",
    "er",
    "erm",
    "ah",
    "hmm",
    "hm",
    "mm",
    "mhm",
    "oh",
    "well",
    "so",
    "like",
    "just",
    "maybe",
    "thanks",
    "thank",
    "cheers",
    "will",
    "should",
    "go ahead and",
    "quickly",
    "right now",
    "very",
    "really",
    "mind",
    "kindly",
    "pretty",
    "i",
    "id",
    "d",
    "ll",
    "s",
    "want",
    "need",
    "would like",
    "let",
    "lets",
    "us",
    "my",
    "your",
    "some",
    "also",
    "again",
    "yourself",
)
POLITENESS_PHRASES: tuple[str, ...] = (
    "could you please",
    "can you please",
    "would you please",
    "please could you",
    "would you mind",
    "if you could",
    "for me please",
    "for me",
    "thank you",
    "i want you to",
    "i would like you to",
    "i d like you to",
)
DETERMINERS: tuple[str, ...] = (
    "the",
    "a",
    "an",
    "this",
    "that",
    "these",
    "those",
    "my",
    "your",
    "some",
    "his",
    "her",
    "our",
    "their",
    "any",
)


def plural(word: str) -> str:
    """English plural of a label's last word ("cup" -> "cups", "wine glass" -> "wine glasses")."""
    head, _, last = word.rpartition(" ")
    irregular = {
        "person": "people",
        "mouse": "mice",
        "knife": "knives",
        "man": "men",
        "woman": "women",
        "child": "children",
        "foot": "feet",
        "skis": "skis",
        "scissors": "scissors",
        "sheep": "sheep",
        "candy": "candies",
        "stuff": "stuff",
        "tv": "tvs",
        "couch": "couches",
    }
    if last in irregular:
        out = irregular[last]
    elif last.endswith(("s", "x", "z", "ch", "sh")):
        out = last + "es"
    elif last.endswith("y") and last[-2:-1] not in "aeiou":
        out = last[:-1] + "ies"
    else:
        out = last + "s"
    return f"{head} {out}" if head else out


def label_matches(said: str | None, label: str) -> bool:
    """Does the language's word `said` (a label, a category or "object") name an object labelled `label`?"""
    if not said or said == ANY_OBJECT:
        return True
    return label == said or label in OBJECT_CATEGORIES.get(said, ())


def phrases(table: dict[str, tuple[str, ...]]) -> dict[str, str]:
    """Flatten a table into phrase -> canonical name."""
    return {p: canonical for canonical, ps in table.items() for p in ps}


def vocabulary() -> set[str]:
    """Every single word the language uses (for grammars and ASR prompts)."""
    words: set[str] = set(FILLER_WORDS) | set(DEICTIC_OBJECT_WORDS) | set(DEICTIC_PLACE_WORDS)
    for table in (
        INTENT_PHRASES,
        REQUEST_PHRASES,
        ANSWER_PHRASES,
        COLOR_PHRASES,
        OBJECT_PHRASES,
        LABEL_PHRASES,
        SPATIAL_PHRASES,
        PLACE_PHRASES,
        MOTION_PHRASES,
        DIRECTION_PHRASES,
        UNIT_PHRASES,
    ):
        for ps in table.values():
            for p in ps:
                words.update(p.split())
    words.update(w for w in NUMBER_WORDS if w.isalpha())
    words.update(w for p in OTHER_PHRASES for w in p.split())
    return words


def prompt_words(limit: int = 120) -> list[str]:
    """The words most worth priming a recogniser with (Whisper's prompt holds ~220 tokens, so not all of
    `vocabulary()`): the first phrase of each intent, motion, direction and unit, the colours, the labels a
    table-top robot meets (COCO household labels, then the rest), the categories and the dialogue words."""
    household = (
        "cup",
        "bottle",
        "bowl",
        "banana",
        "apple",
        "orange",
        "book",
        "cell phone",
        "laptop",
        "remote",
        "scissors",
        "teddy bear",
        "sports ball",
        "wine glass",
        "fork",
        "knife",
        "spoon",
        "keyboard",
        "mouse",
        "person",
        "chair",
        "vase",
        "clock",
        "toothbrush",
        "candy",
        "box",
    )
    ordered: list[str] = []
    for group in (
        [ps[0] for ps in INTENT_PHRASES.values()],
        [ps[0] for ps in MOTION_PHRASES.values()],
        [ps[0] for ps in DIRECTION_PHRASES.values()],
        list(BASIC_COLORS),
        list(household),
        list(OBJECT_CATEGORIES),
        ["the other one", "not that one", "yes", "no", "meters", "degrees", "steps", "centimeters"],
        list(PLACE_PHRASES),
        [label for label in COCO_LABELS if label not in household],
    ):
        ordered.extend(p for p in group if p not in ordered)
    return ordered[:limit]


def canonical_label(detector_label: str) -> str:
    """A detector's label in the language's spelling: lower case, single spaces ("Cell_Phone" -> "cell phone"),
    synonyms to their label ("mug" -> "cup"). Labels the language does not know map to themselves."""
    label = " ".join(detector_label.lower().replace("_", " ").split())
    return LABEL_ALIASES.get(label, label)
