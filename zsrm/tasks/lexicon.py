"""The words of goal sentences: what the grammar of :mod:`zsrm.tasks.language` reads.

Data only. A goal sentence is read as

    [lead words] OBJECT link OBJECT [and OBJECT] [tail words]

where an OBJECT is "[a|an|the] COLOUR [block|cube|puck|object|one]" (or several colours
with one plural noun, "the red and blue blocks") or "[a|the] box", and a link is some
filler words then exactly one relation phrase ("should be | right | on top of"). Every word of the sentence
must have a place in that pattern; a sentence with a word that has none is refused.
"""
from __future__ import annotations

COLOURS = ("red", "green", "yellow", "blue")
SHAPES = ("block", "puck")

# Colour words that name no object zsrm has: "unknown colour", never a guess.
OTHER_COLOURS = frozenset({
    "purple", "orange", "pink", "black", "white", "brown", "grey", "gray", "cyan", "magenta", "violet",
    "gold", "golden", "silver", "beige", "teal", "turquoise", "navy", "maroon", "indigo", "lime",
})

# Nouns for an object and the shape each means; None: the shape of the other nouns ("the red one").
SHAPE_WORDS = {
    "block": "block", "blocks": "block", "cube": "block", "cubes": "block",
    "puck": "puck", "pucks": "puck",
    "object": None, "objects": None, "one": None, "ones": None,
}
# The tabletop's one open box. It has no colour, so a goal names it by its noun alone ("put the
# red block into the box"); in a Task it is the object "box", beside the colours.
CONTAINERS = ("box",)
BOX = CONTAINERS[0]
CONTAINER_WORDS = {"box": "box", "container": "box"}
DETERMINERS = frozenset({"a", "an", "the"})
# Words between the determiner and the colour (or "box") that change nothing: all blocks are alike,
# and there is one box, an open one.
ADJECTIVES = frozenset({"small", "little", "tiny", "big", "large", "open"})
SELF_WORDS = frozenset({"itself", "themselves"})
# Counting words: "two blocks" names blocks but not which ones.
QUANTIFIERS = frozenset({"two", "three", "four", "both", "all", "every", "some", "any", "other", "another"})
NEGATIONS = frozenset({"not", "never", "no", "nor", "without", "nowhere", "neither"})

# Relation phrases as regular expressions over the normalised sentence (lower case, single
# spaces, "block's" written "block 's"). Each relation also lists plain wordings below.
_SIDE = r"(?:(?:to|on|at|onto) )?(?:the )?{side}(?: hand)?(?: side)? of"
RELATION_PATTERNS = {
    "left_of": (_SIDE.format(side="left"),),
    "right_of": (_SIDE.format(side="right"),),
    "on_top_of": (r"on|onto|on to|upon|atop|above", r"(?:on|onto|on to|at) (?:the )?top of"),
    "below": (r"(?:below|under|underneath|beneath)(?: of)?",),
    "in_between": (r"(?:in )?between", r"(?:midway|halfway) between", r"in the middle of"),
    "in_front_of": (r"(?:in|to|at) (?:the )?front of",),
    "behind": (r"behind", r"(?:in|at|to) (?:the )?back of"),
    "close_to": (r"close to|close by|close beside|near|near to|nearby|next to|beside|by|alongside|adjacent to",),
    "inside_of": (r"inside|inside of|in|into|in to|within",),
}

# Plain wordings of each relation (the canonical phrase first): for messages, for the
# nearest-wording hint on a misspelt relation, and for checks that captions hold none of them.
RELATION_WORDS = {
    "left_of": ("on the left of", "to the left of", "left of", "on the left side of", "to the left hand side of"),
    "right_of": ("on the right of", "to the right of", "right of", "on the right side of",
                 "to the right hand side of"),
    "on_top_of": ("on top of", "onto", "on", "atop", "above", "upon"),
    "below": ("below", "under", "beneath", "underneath"),
    "in_between": ("in between", "between", "in the middle of"),
    "in_front_of": ("in front of", "to the front of"),
    "behind": ("behind", "in back of", "at the back of"),
    "close_to": ("close to", "near", "next to", "beside", "close by", "adjacent to", "alongside"),
    "inside_of": ("inside of", "inside", "into", "in", "within"),
}

# "to the red block's right": the side after the possessive, and the relation it names.
POSSESSIVE_SIDES = {"left": "left_of", "right": "right_of", "front": "in_front_of", "back": "behind",
                    "rear": "behind", "top": "on_top_of"}
POSSESSIVE_LINK = r"(?:to|on|at|onto|in|by)"
POSSESSIVE_TAIL = r"(?: hand)?(?: side)?"
# "the blue and yellow pucks next to each other" (symmetric relations only).
EACH_OTHER = r"(?:each other|one another)"

# Words a link may hold before its relation phrase: copulas, verbs of placing, particles,
# adverbs that do not change the relation ("right next to", "directly below").
LINK_FILLERS = frozenset("""
    is are be being been should must will would can could needs need has have to so that it they then
    gets get got go goes going end ends ending up down over stay stays sit sits sitting sat rest rests
    resting lie lies lying stand stands standing placed put set positioned located stacked moved pushed
    slid dropped kept lands land right directly just immediately exactly precisely squarely neatly
    carefully gently quickly slowly firmly also somewhere slightly a little bit
""".split())

# Verbs of placing an object: they start a goal ("put the red block ...") and take up an
# object again ("pick up the red block and put it on ...").
PLACING_VERBS = frozenset("""
    put place move stack push bring set slide drop position lay stick hide shift carry arrange leave
    keep get nudge pull drag lift lower transfer relocate
""".split())

# Words before the first object: framing, politeness and the verbs of placing.
LEAD_WORDS = PLACING_VERBS | frozenset("""
    please kindly can could would will you i we want wanted need like love let us now then first next
    finally go ahead and ok okay so make sure that try to goal task is should just also hey robot
    image photo picture of show me have the a an pick up
""".split())

# Words after the last object.
TAIL_WORDS = frozenset("please thanks thank you now for me again ok okay then".split())
