"""Goal sentences over a user's own scene: Table 1's relations between the objects a scene
adapter names by its noun phrases (:attr:`zsrm.envs.SceneAdapter.objects`), where zsrm's own
goals name a colour and block / puck.

The sentence is read as zsrm's own goals are (:mod:`zsrm.tasks.language`: the same lead, link
and tail words, the same relation phrases of :data:`zsrm.tasks.relations.RELATIONS`), with
the scene's phrases as the objects. Every refusal is a :class:`~zsrm.tasks.language.GoalError`
(a ValueError) of one line that lists the scene's objects.

>>> phrases = ("red mug", "blue plate", "orange spoon")
>>> goal = parse_scene_goal("put the red mug onto the blue plate", phrases)
>>> goal.relation, goal.objects
('on_top_of', ('red mug', 'blue plate'))
>>> parse_scene_goal("a red mug close to an orange spoon", phrases).text
'a red mug close to an orange spoon'
>>> parse_scene_goal("a green cup on the left of a red mug", phrases)
Traceback (most recent call last):
...
zsrm.tasks.language.GoalError: cannot read 'a green cup on the left of a red mug': unknown object 'green cup'; this scene's objects: red mug, blue plate, orange spoon
"""
from __future__ import annotations

import re
from dataclasses import dataclass

from zsrm.tasks.language import (GoalError, _check_words, _Mention, _normalise, _quote, _Refusal, _relate,
                                 check_objects, goal_sentence)
from zsrm.tasks.lexicon import (DETERMINERS, EACH_OTHER, LEAD_WORDS, LINK_FILLERS, NEGATIONS, POSSESSIVE_SIDES,
                                RELATION_PATTERNS, TAIL_WORDS)
from zsrm.tasks.relations import RELATIONS

# A noun phrase, as an adapter's objects are written (zsrm.envs.adapter checks them the same way).
_PHRASE = re.compile(r"^[a-z]+(?: [a-z]+)*$")
# The words of a goal that are not objects: any other word outside an object is an unknown object.
_GRAMMAR_WORDS = frozenset(
    LEAD_WORDS | TAIL_WORDS | LINK_FILLERS | DETERMINERS | set(POSSESSIVE_SIDES) | {"and", "'s", "hand", "side"}
    | {w for ps in RELATION_PATTERNS.values() for p in ps for w in re.findall(r"[a-z]+", p)}
    | set(re.findall(r"[a-z]+", EACH_OTHER)))


@dataclass(frozen=True)
class SceneGoal:
    """A spatial goal over an own scene's objects: ``relation`` over noun phrases ``objects``.
    It has the :class:`~zsrm.tasks.language.Task` fields the negatives read (``relation``,
    ``objects``, ``phrases``, ``text``)."""

    relation: str
    objects: tuple[str, ...]

    def __post_init__(self):
        object.__setattr__(self, "objects", tuple(self.objects))
        if self.relation not in RELATIONS:
            raise GoalError(f"unknown relation {self.relation!r}; known relations: {', '.join(RELATIONS)}")
        for phrase in self.objects:
            if not isinstance(phrase, str) or not _PHRASE.match(phrase):
                raise GoalError(f"object {phrase!r} is not a noun phrase of lower-case words")
        check_objects(self.relation, self.objects)

    @property
    def phrases(self) -> tuple[str, ...]:
        return self.objects

    @property
    def text(self) -> str:
        """The canonical goal sentence ("a red mug on top of an orange plate")."""
        return goal_sentence(self.relation, self.objects)

    def __str__(self) -> str:
        return self.text


def _mentions(tokens: list[str], phrases: tuple[str, ...]) -> list[_Mention]:
    """The scene's objects named in the tokens, each with its determiner; the longest phrase wins."""
    words = sorted((p.split() for p in phrases), key=len, reverse=True)
    found, i = [], 0
    while i < len(tokens):
        j = i + (tokens[i] in DETERMINERS)
        match = next((w for w in words if tokens[j:j + len(w)] == w), None)
        if match is None:
            i += 1
            continue
        # An own scene's phrase stands where a colour does in zsrm's grammar (no noun after it).
        found.append(_Mention([" ".join(match)], None, i, j + len(match)))
        i = j + len(match)
    return found


def _unknown_words(tokens: list[str], mentions: list[_Mention]) -> str | None:
    """The first run of words outside the scene's objects that the grammar does not know."""
    inside = {k for m in mentions for k in range(m.start, m.end)}
    run: list[str] = []
    for k, w in enumerate(tokens):
        if k not in inside and w not in _GRAMMAR_WORDS:
            run.append(w)
        elif run:
            break
    return " ".join(run) or None


def _read(tokens: list[str], phrases: tuple[str, ...]) -> SceneGoal:
    negation = next((t for t in tokens if t in NEGATIONS), None)
    if negation:
        raise _Refusal("negation", f"the goal says {negation!r}",
                       "write the relation that should hold, not one that should not")
    mentions = _mentions(tokens, phrases)
    if len(mentions) < 2:
        unknown = _unknown_words(tokens, mentions)
        if unknown:
            raise _Refusal("unknown object", f"unknown object {_quote(unknown)}")
        raise _Refusal("one object" if mentions else "no object",
                       f"only one object ({mentions[0].phrase})" if mentions else "no object of this scene",
                       "a goal relates two objects (three for in between)")
    named = [m.colours[0] for m in mentions]
    twice = next((p for k, p in enumerate(named) if p in named[:k]), None)
    if twice:
        raise _Refusal("same object", f"a goal must name different objects, got the {twice} twice")
    relation, objects, tail_start = _relate(tokens, mentions)
    _check_words(tokens, mentions[0].start, tail_start)
    return SceneGoal(relation, tuple(objects))


def read_canonical(text: str) -> SceneGoal:
    """The SceneGoal of a canonical sentence (:attr:`SceneGoal.text`: how the labeler writes an
    own scene's captions) without the scene's object list: the one reading whose text gives
    ``text`` back. GoalError when none does, or more than one.

    >>> read_canonical("an orange mug close to a blue plate").objects
    ('orange mug', 'blue plate')
    """
    words, tokens, found = r"[a-z]+(?: [a-z]+)*", text.split(), []
    for name, rel in RELATIONS.items():
        rest = rf"{rel.phrase} an? ({words})" + (rf" and an? ({words})" if rel.arity == 3 else "")
        for k in range(2, len(tokens)):  # every split after the first phrase: a phrase may hold a relation's words
            first, others = re.fullmatch(rf"an? ({words})", " ".join(tokens[:k])), re.fullmatch(rest, " ".join(tokens[k:]))
            if first and others:
                try:
                    goal = SceneGoal(name, (first.group(1), *others.groups()))
                except GoalError:
                    continue
                if goal.text == text and goal not in found:
                    found.append(goal)
    if len(found) != 1:
        raise GoalError(f"{text!r} has {len(found) or 'no'} reading{'s' * (len(found) != 1)} as a canonical goal sentence "
                        "(\"a red mug on top of a blue plate\")")
    return found[0]


def parse_scene_goal(text: str, phrases, scene: str = "this scene") -> SceneGoal:
    """Read a goal sentence over a scene whose objects are ``phrases`` (an adapter's objects).

    GoalError of one line for anything the grammar does not read: what is wrong, the known
    relations where the relation is wrong, and always the scene's objects.
    """
    phrases = tuple(phrases)
    objects = f"{scene}'s objects: {', '.join(phrases)}"
    if not isinstance(text, str) or not text.strip():
        raise GoalError(f"empty goal: write a sentence such as {SceneGoal('close_to', phrases[:2]).text!r}; "
                        f"{objects}" if len(phrases) > 1 else f"empty goal; {objects}", "empty")
    try:
        return _read(_normalise(text), phrases)
    except _Refusal as r:
        suggestion = None
        if r.fix:
            try:
                suggestion = _read(r.fix, phrases).text
            except (_Refusal, GoalError):
                pass
        message = f"cannot read {_quote(text, width=160)}: {r.what}" + (f"; {r.hint}" if r.hint else "")
        message += (f"; did you mean {suggestion!r}?" if suggestion else "") + f"; {objects}"
        raise GoalError(message, r.reason, suggestion) from None
