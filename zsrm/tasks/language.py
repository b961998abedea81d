"""Goal sentences and tasks, both ways.

A goal is read by a small deterministic grammar (the words are in :mod:`zsrm.tasks.lexicon`):

    [lead words] OBJECT link OBJECT [and OBJECT] [tail words]

An OBJECT is "[a|an|the] COLOUR [block|cube|puck|object|one]", or several colours with one
noun ("the red and blue blocks"); a link is filler words ("should be", "right") then exactly
one relation phrase. "to the red block's right" and "the blue and yellow pucks next to each
other" are the two other forms. Every word must have a place in the pattern: a sentence with
a word that has none, or without two objects and a relation, is refused with a
:class:`GoalError` whose one-line message says what is wrong and, where there is one, the
nearest goal zsrm does understand. Nothing is guessed.

>>> task = Task.from_text("a yellow block on the right of a red block")
>>> task.relation, task.objects
('right_of', ('yellow', 'red'))
>>> task.text
'a yellow block on the right of a red block'
>>> parse_goal("Put the red block onto the yellow one.").text
'a red block on top of a yellow block'
>>> parse_goal("push the blue puck to the yellow puck's left").relation
'left_of'
"""
from __future__ import annotations

import difflib
import re
from dataclasses import dataclass, replace

from zsrm.tasks.lexicon import (ADJECTIVES, COLOURS, CONTAINER_WORDS, CONTAINERS, DETERMINERS, EACH_OTHER, LEAD_WORDS, LINK_FILLERS, NEGATIONS,
                                OTHER_COLOURS, PLACING_VERBS, POSSESSIVE_LINK, POSSESSIVE_SIDES, POSSESSIVE_TAIL,
                                QUANTIFIERS, RELATION_PATTERNS, RELATION_WORDS, SELF_WORDS, SHAPE_WORDS, SHAPES,
                                TAIL_WORDS)
from zsrm.tasks.relations import RELATIONS

assert set(RELATION_WORDS) == set(RELATION_PATTERNS) == set(RELATIONS)

# Why a goal is refused: GoalError.reason is one of these.
REFUSAL_REASONS = ("empty", "negation", "unknown colour", "unknown object", "no colour", "mixed objects",
                   "same object", "no object", "one object", "no relation", "object count", "extra words")


class GoalError(ValueError):
    """A goal sentence or task that zsrm cannot understand; the message says what is known.

    ``reason`` is one of :data:`REFUSAL_REASONS` (None for a bad :class:`Task`) and
    ``suggestion`` the canonical text of the nearest goal zsrm understands, if there is one.
    """

    def __init__(self, message: str, reason: str | None = None, suggestion: str | None = None):
        super().__init__(message)
        self.reason = reason
        self.suggestion = suggestion


@dataclass(frozen=True)
class Task:
    """A spatial goal: ``relation`` over ``objects`` (colours, or the tabletop's "box"), the
    coloured ones all of one ``shape``."""

    relation: str
    objects: tuple[str, ...]
    shape: str = "block"

    def __post_init__(self):
        object.__setattr__(self, "objects", tuple(self.objects))
        if self.relation not in RELATIONS:
            raise GoalError(f"unknown relation {self.relation!r}; known relations: {', '.join(RELATIONS)}")
        if self.shape not in SHAPES:
            raise GoalError(f"unknown object {self.shape!r}; known objects: {', '.join(SHAPES)}")
        for colour in self.objects:
            if colour in CONTAINERS and self.shape != "block":
                raise GoalError(f"the {colour} is on the tabletop, with blocks, not with {self.shape}s")
            if colour not in COLOURS and colour not in CONTAINERS:
                raise GoalError(f"unknown colour {colour!r}; known colours: {', '.join(COLOURS)}")
        check_objects(self.relation, self.objects)

    @property
    def text(self) -> str:
        """The canonical goal sentence."""
        return goal_sentence(self.relation, self.phrases)

    @property
    def phrases(self) -> tuple[str, ...]:
        """Noun phrases of the objects, as Grad-CAM reads them ("red block")."""
        return tuple(c if c in CONTAINERS else f"{c} {self.shape}" for c in self.objects)

    @property
    def has_container(self) -> bool:
        """Does the goal name a container (the box)?"""
        return any(c in CONTAINERS for c in self.objects)

    def mirrored(self) -> "Task":
        """The goal of the scene mirrored left to right in its camera ("left of" <-> "right of");
        a ValueError for a relation whose camera's image does not simply flip."""
        mirror = RELATIONS[self.relation].mirror
        if mirror is None:
            raise ValueError(f"{self.relation} is read by the {RELATIONS[self.relation].camera} camera, whose "
                             "image does not flip with the scene's left and right")
        return replace(self, relation=mirror)

    @property
    def scene(self) -> str:
        return "pushing" if self.shape == "puck" else "tabletop"

    @classmethod
    def from_text(cls, text: str) -> "Task":
        return parse_goal(text)

    def __str__(self) -> str:
        return self.text


def check_objects(relation: str, objects: tuple[str, ...]) -> None:
    """As many objects as the relation relates, all different (a Task's or an own scene's goal)."""
    arity = RELATIONS[relation].arity
    if len(objects) != arity:
        raise GoalError(f"{relation} relates {arity} objects, got {len(objects)}")
    if len(set(objects)) != len(objects):
        raise GoalError(f"a goal must name different objects, got {', '.join(objects)}")


def goal_sentence(relation: str, phrases: tuple[str, ...]) -> str:
    """The canonical sentence of ``relation`` over noun phrases: "a red mug on top of an orange plate"."""
    names = [with_article(p) for p in phrases]
    rel = RELATIONS[relation]
    if rel.arity == 3:
        return f"{names[0]} {rel.phrase} {names[1]} and {names[2]}"
    return f"{names[0]} {rel.phrase} {names[1]}"


def with_article(phrase: str) -> str:
    """A noun phrase with its indefinite article: "a red block", "an orange plate"."""
    return f"{'an' if phrase[:1] in 'aeiou' else 'a'} {phrase}"


# --- reading a sentence ------------------------------------------------------------------

_CONTRACTIONS = (
    (r"\b(it|that|what|there|he|she)'s\b", r"\1 is"), (r"\blet's\b", "let us"), (r"\bcan't\b", "can not"),
    (r"\bwon't\b", "will not"), (r"n't\b", " not"), (r"'d\b", " would"), (r"'m\b", " am"), (r"'ll\b", " will"),
    (r"'re\b", " are"), (r"'ve\b", " have"), (r"(\w)'s\b", r"\1 's"),
)


def _normalise(text: str) -> list[str]:
    """Lower case words; "block's" becomes "block 's", contractions are spelt out, other
    punctuation and hyphens are spaces."""
    s = text.lower().replace("\u2019", "'").replace("`", "'")
    for pattern, repl in _CONTRACTIONS:
        s = re.sub(pattern, repl, s)
    s = re.sub(r"[^\w\s']", " ", s.replace("_", " "))
    return [t if t == "'s" else t.strip("'") for t in s.split() if t.strip("'")]


def _pattern_words(patterns) -> set[str]:
    return {w for p in patterns for w in re.findall(r"[a-z]+", p)}


VOCABULARY = frozenset(
    set(COLOURS) | OTHER_COLOURS | set(SHAPE_WORDS) | set(CONTAINER_WORDS) | DETERMINERS | ADJECTIVES | SELF_WORDS
    | NEGATIONS | LINK_FILLERS | LEAD_WORDS | TAIL_WORDS | QUANTIFIERS | set(POSSESSIVE_SIDES) | {"and", "'s", "each"}
    | _pattern_words([p for ps in RELATION_PATTERNS.values() for p in ps] + [POSSESSIVE_LINK, POSSESSIVE_TAIL])
)
_FILLERS = "|".join(sorted(LINK_FILLERS | {"please"}))
# "pick up the red block and put it on ...": the object taken up again by "it".
_RESUME = rf"(?:and (?:{'|'.join(sorted(PLACING_VERBS))}) it )?"
_LINKS = {rel: re.compile(rf"^{_RESUME}(?:(?:{_FILLERS}) )*(?:{'|'.join(ps)})$")
          for rel, ps in RELATION_PATTERNS.items()}
_POSSESSIVE_LINK = re.compile(rf"^{_RESUME}(?:(?:{_FILLERS}) )*{POSSESSIVE_LINK}$")
_POSSESSIVE = re.compile(rf"^'s ({'|'.join(POSSESSIVE_SIDES)}){POSSESSIVE_TAIL}(?= |$)")
_EACH_OTHER = re.compile(rf"^(.*?) ?{EACH_OTHER}(?= |$)")


@dataclass
class _Mention:
    """An object phrase: its colour words, its noun as written, where it is in the tokens."""

    colours: list[str]
    noun: str | None
    start: int
    end: int
    self_ref: bool = False  # "itself"

    @property
    def phrase(self) -> str:
        """"red block", "red and green blocks", "red" (as written, for messages)."""
        colours = " and ".join(filter(None, [", ".join(self.colours[:-1]), self.colours[-1]])) if self.colours else ""
        return f"{colours} {self.noun or ''}".strip()


class _Refusal(Exception):
    def __init__(self, reason: str, what: str, hint: str = "", fix: list[str] | None = None):
        super().__init__(what)
        self.reason, self.what, self.hint, self.fix = reason, what, hint, fix


def _tok(tokens: list[str], i: int) -> str | None:
    return tokens[i] if 0 <= i < len(tokens) else None


def _is_colour(tokens: list[str], i: int) -> bool:
    """A colour word, known or not; an unknown word right before an object noun counts too."""
    w, nxt = _tok(tokens, i), _tok(tokens, i + 1)
    if w is None:
        return False
    if w in COLOURS or w in OTHER_COLOURS:
        return True
    return w not in VOCABULARY and nxt in SHAPE_WORDS and nxt not in ("one", "ones")


def _colour_list(tokens: list[str], j: int) -> tuple[list[str], int]:
    """Colours from ``j``: "red", "red and blue", "red green and the blue"."""
    colours = [tokens[j]]
    j += 1
    while True:
        k = j
        if _tok(tokens, k) == "and":
            k += 1 + (_tok(tokens, k + 1) in DETERMINERS)
        if not _is_colour(tokens, k):
            return colours, j
        colours.append(tokens[k])
        j = k + 1


def _mention_at(tokens: list[str], i: int) -> _Mention | None:
    """The object phrase starting at token ``i``, if one does."""
    j = i + (_tok(tokens, i) in DETERMINERS)
    while _tok(tokens, j) in ADJECTIVES:
        j += 1
    w = _tok(tokens, j)
    if w in SELF_WORDS:
        return _Mention([], None, i, j + 1, self_ref=True)
    if w in CONTAINER_WORDS:  # "the box": the container is its own name, it has no colour
        return _Mention([CONTAINER_WORDS[w]], None, i, j + 1)
    if not _is_colour(tokens, j):
        has_det = j > i
        if w in SHAPE_WORDS and (has_det or w not in ("one", "ones")):
            return _Mention([], w, i, j + 1)  # "the block": no colour
        end = j
        while has_det and _tok(tokens, end) is not None and _tok(tokens, end) not in VOCABULARY:
            end += 1
        return _Mention([], " ".join(tokens[j:end]), i, end) if end > j else None  # "the table": unknown
    colours, j = _colour_list(tokens, j)
    noun = _tok(tokens, j)
    if noun is None or (noun in VOCABULARY and noun not in SHAPE_WORDS and noun not in CONTAINER_WORDS):
        return _Mention(colours, None, i, j)  # a bare colour: "stack red on blue"
    return _Mention(colours, noun, i, j + 1)


def _chunk(tokens: list[str]) -> list[_Mention]:
    mentions, i = [], 0
    while i < len(tokens):
        m = _mention_at(tokens, i)
        if m is None:
            i += 1
        else:
            mentions.append(m)
            i = m.end
    return mentions


def _quote(words: str, width: int = 60) -> str:
    """Words of the sentence, quoted for a message: on one line, shortened when long."""
    words = " ".join(words.split())
    return repr(words if len(words) <= width else words[:width - 4].rsplit(" ", 1)[0] + " ...")


def _closest(word: str, known) -> str | None:
    match = difflib.get_close_matches(word, list(known), n=1, cutoff=0.6)
    return match[0] if match else None


def _replaced(tokens: list[str], swaps: dict[str, str | None]) -> list[str] | None:
    """The tokens with words swapped (a fix to try), None if some word has no replacement."""
    if any(v is None for v in swaps.values()):
        return None
    return [swaps.get(t, t) for t in tokens]


def _check_objects(tokens: list[str], mentions: list[_Mention]) -> str:
    """The shape the objects share; _Refusal for anything wrong with the objects themselves."""
    colours = [c for m in mentions for c in m.colours]
    _check_container(tokens, mentions)
    unknown = [c for c in colours if c not in COLOURS and c not in CONTAINERS]
    if unknown:
        raise _Refusal("unknown colour", f"unknown colour {_quote(unknown[0])}", f"known colours: {', '.join(COLOURS)}",
                       _replaced(tokens, {c: _closest(c, COLOURS) for c in unknown}))
    nouns = [m.noun for m in mentions if m.noun is not None and m.noun not in SHAPE_WORDS]
    if nouns:
        raise _Refusal("unknown object", f"unknown object {_quote(nouns[0])}",
                       f"known objects: {', '.join(SHAPES)} (also cube, object, one), box",
                       _replaced(tokens, {n: _closest(n, ("block", "cube", "puck", "box")) or "object" for n in nouns}))
    colourless = next((m for m in mentions if not m.colours and not m.self_ref), None)
    if colourless is not None:
        raise _Refusal("no colour", f"{_quote(' '.join(tokens[colourless.start:colourless.end]))} names no colour",
                       f"name each object by its colour: {', '.join(COLOURS)}")
    shapes = {SHAPE_WORDS[m.noun] for m in mentions if m.noun} - {None}
    if len(shapes) > 1:
        first = next(SHAPE_WORDS[m.noun] for m in mentions if m.noun and SHAPE_WORDS[m.noun])
        swaps = {w: "object" for w, s in SHAPE_WORDS.items() if s not in (None, first)}
        raise _Refusal("mixed objects", f"a goal relates objects of one kind, got {' and '.join(sorted(shapes))}",
                       fix=_replaced(tokens, swaps))
    twice = next((c for i, c in enumerate(colours) if c in colours[:i]), None)
    if twice or any(m.self_ref for m in mentions):
        got = (f"the {twice} twice" if twice in CONTAINERS else f"the {twice} one twice") if twice \
            else f"the {mentions[0].phrase} and itself"
        raise _Refusal("same object", f"a goal must name different objects, got {got}")
    if len(colours) < 2:
        what = f"only one object ({mentions[0].phrase})" if colours else "no coloured block or puck"
        raise _Refusal("one object" if colours else "no object", what,
                       "a goal relates two objects (three for in between)")
    return shapes.pop() if shapes else "block"


def _check_container(tokens: list[str], mentions: list[_Mention]) -> None:
    """_Refusal for a box with a colour ("the red box") or beside pucks (it is on the tabletop)."""
    coloured = next((m for m in mentions if m.noun in CONTAINER_WORDS), None)
    if coloured is not None:
        raise _Refusal("unknown object", f"{_quote(' '.join(tokens[coloured.start:coloured.end]))}: the box has "
                       "no colour", "name it 'the box'", tokens[:coloured.start] + ["the", "box"] + tokens[coloured.end:])
    pucks = any(m.noun and SHAPE_WORDS.get(m.noun) == "puck" for m in mentions)
    if pucks and any(c in CONTAINERS for m in mentions for c in m.colours):
        raise _Refusal("mixed objects", "the box is on the tabletop, with blocks, not with pucks",
                       fix=_replaced(tokens, {"puck": "block", "pucks": "blocks"}))


def _link_relation(link: str) -> str | None:
    """The relation a link between two objects names ("should be right next to": close_to)."""
    return next((rel for rel, pattern in _LINKS.items() if pattern.match(link)), None)


def _possessive(link: str, tail: str) -> tuple[str | None, int]:
    """"to the red block's right": the relation and how many tail words it takes."""
    m = _POSSESSIVE.match(tail)
    if m is None or not _POSSESSIVE_LINK.match(link):
        return None, 0
    return POSSESSIVE_SIDES[m.group(1)], len(m.group(0).split())


def _no_relation(tokens: list[str], mentions: list[_Mention], link: str | None) -> _Refusal:
    """The refusal for two objects without a relation; the fix respells a misspelt one."""
    known = ", ".join(RELATION_WORDS[r][0] for r in RELATIONS)
    names = " and ".join(f"the {m.phrase}" for m in mentions[:2])
    what = f"no relation between {names}" + (f" ({_quote(link)} is not one)" if link else "")
    fix = None
    words = (link or "").split()
    wordings = [w for ws in RELATION_WORDS.values() for w in ws]
    for n in range(1, min(4, len(words)) + 1):
        match = difflib.get_close_matches(" ".join(words[-n:]), wordings, n=1, cutoff=0.8)
        if match and len(mentions) > 1:
            a, b = mentions[0], mentions[1]
            fix = tokens[:a.end] + words[:-n] + match[0].split() + tokens[b.start:]
            break
    return _Refusal("no relation", what, f"known relations: {known}", fix)


def _relate(tokens: list[str], mentions: list[_Mention]) -> tuple[str, list[str], int]:
    """The relation, the colours in order, and where the words after the goal start."""
    colours = [c for m in mentions for c in m.colours]
    tail_start = mentions[-1].end
    tail = " ".join(tokens[tail_start:])
    links = [" ".join(tokens[a.end:b.start]) for a, b in zip(mentions, mentions[1:])]
    if all(link == "and" for link in links):  # "the blue and yellow pucks next to each other"
        m = _EACH_OTHER.match(tail)
        if m and len(colours) == 2 and _link_relation(m.group(1)) == "close_to":
            return "close_to", colours, tail_start + len(m.group(0).split())
        if len(mentions) == 1:
            raise _no_relation(tokens, mentions, None)
    # "on the yellow block's left": the side after the possessive is the relation, not "on".
    relation, used = _possessive(links[0], tail) if len(mentions) == 2 else (None, 0)
    tail_start += used
    relation = relation or _link_relation(links[0])
    if relation is None:
        raise _no_relation(tokens, mentions, links[0])
    sizes = [len(m.colours) for m in mentions]
    if relation == "in_between":
        fits = sizes[0] == 1 and len(colours) == 3 and all(link == "and" for link in links[1:])
    else:
        fits = sizes == [1, 1]
    if not fits:
        arity = RELATIONS[relation].arity
        raise _Refusal("object count", f"{RELATION_WORDS[relation][0]!r} relates {arity} objects, "
                                       f"the goal names {len(colours)} ({', '.join(colours)})")
    return relation, colours, tail_start


def _check_words(tokens: list[str], lead_end: int, tail_start: int) -> None:
    """Words before the first object and after the goal must be ones zsrm knows to mean nothing."""
    lead, tail = tokens[:lead_end], tokens[tail_start:]
    unknown = [w for w in lead if w not in LEAD_WORDS] + [w for w in tail if w not in TAIL_WORDS]
    if unknown:
        keep_lead = all(w in LEAD_WORDS for w in lead)
        keep_tail = all(w in TAIL_WORDS for w in tail)
        fix = (lead if keep_lead else []) + tokens[lead_end:tail_start] + (tail if keep_tail else [])
        raise _Refusal("extra words", f"words zsrm cannot read: {_quote(' '.join(unknown))}", fix=fix)


def _read(tokens: list[str]) -> Task:
    negation = next((t for t in tokens if t in NEGATIONS), None)
    if negation:
        raise _Refusal("negation", f"the goal says {negation!r}",
                       "write the relation that should hold, not one that should not")
    mentions = _chunk(tokens)
    shape = _check_objects(tokens, mentions)
    relation, colours, tail_start = _relate(tokens, mentions)
    _check_words(tokens, mentions[0].start, tail_start)
    return Task(relation, tuple(colours), shape)


def _suggest(tokens: list[str] | None) -> str | None:
    """The canonical text of the goal a fixed sentence reads as, if it reads as one."""
    if not tokens:
        return None
    try:
        return _read(tokens).text
    except (_Refusal, GoalError):
        return None


def parse_goal(text: str) -> Task:
    """Read a goal sentence ("put the red block onto the yellow one") as a Task.

    GoalError (with ``reason`` and ``suggestion``) for anything the grammar does not read; its
    message is one line: what is wrong, what is known, and the nearest goal that reads, if any.
    """
    if not isinstance(text, str) or not text.strip():
        raise GoalError("empty goal: write a sentence such as 'a yellow block on top of a red block'", "empty")
    shown = _quote(text, width=160)
    try:
        return _read(_normalise(text))
    except _Refusal as r:
        suggestion = _suggest(r.fix)
        message = f"cannot read {shown}: {r.what}" + (f"; {r.hint}" if r.hint else "")
        message += f"; did you mean {suggestion!r}?" if suggestion else ""
        raise GoalError(message, r.reason, suggestion) from None
