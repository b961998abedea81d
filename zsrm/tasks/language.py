"""Goal sentences and tasks, both ways.

>>> task = Task.from_text("a yellow block on the right of a red block")
>>> task.relation, task.objects
('right_of', ('yellow', 'red'))
>>> task.text
'a yellow block on the right of a red block'
"""
from __future__ import annotations

import re
from dataclasses import dataclass

from zsrm.tasks.relations import RELATIONS

COLOURS = ("red", "green", "yellow", "blue")
SHAPES = ("block", "puck")
# Words a user may write for a shape; the canonical one renders.
SHAPE_WORDS = {"block": "block", "cube": "block", "puck": "puck", "object": None}

# Accepted wordings of each relation, longest first when matching.
RELATION_WORDS = {
    "left_of": ("on the left of", "to the left of", "left of"),
    "right_of": ("on the right of", "to the right of", "right of"),
    "on_top_of": ("on top of", "stacked on", "on"),
    "below": ("below", "under", "beneath", "underneath"),
    "in_between": ("in between", "between"),
    "in_front_of": ("in front of",),
    "behind": ("behind",),
    "close_to": ("close to", "near", "next to"),
    "inside_of": ("inside of", "inside", "in"),
}
assert set(RELATION_WORDS) == set(RELATIONS)


class GoalError(ValueError):
    """A goal sentence or task that zsrm cannot understand; the message says what is known."""


@dataclass(frozen=True)
class Task:
    """A spatial goal: ``relation`` over ``objects`` (colours), all of one ``shape``."""

    relation: str
    objects: tuple[str, ...]
    shape: str = "block"

    def __post_init__(self):
        object.__setattr__(self, "objects", tuple(self.objects))
        if self.relation not in RELATIONS:
            raise GoalError(f"unknown relation {self.relation!r}; known relations: {', '.join(RELATIONS)}")
        for colour in self.objects:
            if colour not in COLOURS:
                raise GoalError(f"unknown colour {colour!r}; known colours: {', '.join(COLOURS)}")
        if self.shape not in SHAPES:
            raise GoalError(f"unknown object {self.shape!r}; known objects: {', '.join(SHAPES)}")
        arity = RELATIONS[self.relation].arity
        if len(self.objects) != arity:
            raise GoalError(f"{self.relation} relates {arity} objects, got {len(self.objects)}")
        if len(set(self.objects)) != len(self.objects):
            raise GoalError(f"a goal must name different objects, got {', '.join(self.objects)}")

    @property
    def text(self) -> str:
        """The canonical goal sentence."""
        names = [f"a {c} {self.shape}" for c in self.objects]
        rel = RELATIONS[self.relation]
        if rel.arity == 3:
            return f"{names[0]} {rel.phrase} {names[1]} and {names[2]}"
        return f"{names[0]} {rel.phrase} {names[1]}"

    @property
    def phrases(self) -> tuple[str, ...]:
        """Noun phrases of the objects, as Grad-CAM reads them ("red block")."""
        return tuple(f"{c} {self.shape}" for c in self.objects)

    @property
    def scene(self) -> str:
        return "pushing" if self.shape == "puck" else "tabletop"

    @classmethod
    def from_text(cls, text: str) -> "Task":
        return parse_goal(text)

    def __str__(self) -> str:
        return self.text


_OBJECT = r"(?:a|an|the)\s+(\w+)\s+(\w+)"


def _parse_object(colour: str, shape_word: str) -> tuple[str, str | None]:
    if colour not in COLOURS:
        raise GoalError(f"unknown colour {colour!r}; known colours: {', '.join(COLOURS)}")
    if shape_word not in SHAPE_WORDS:
        raise GoalError(f"unknown object {shape_word!r}; known objects: {', '.join(SHAPE_WORDS)}")
    return colour, SHAPE_WORDS[shape_word]


def parse_goal(text: str) -> Task:
    """Parse a goal sentence such as "a yellow block on top of a red block" into a Task."""
    if not isinstance(text, str) or not text.strip():
        raise GoalError("empty goal: write a sentence such as 'a yellow block on top of a red block'")
    s = re.sub(r"[^\w\s]", " ", text.lower())
    s = re.sub(r"\s+", " ", s).strip()
    s = re.sub(r"^(?:an? )?(?:image|photo|picture) of ", "", s)
    for relation, wordings in sorted(RELATION_WORDS.items(), key=lambda kv: -max(map(len, kv[1]))):
        for words in wordings:
            if RELATIONS[relation].arity == 3:
                pattern = rf"^{_OBJECT} {words} {_OBJECT} and {_OBJECT}$"
            else:
                pattern = rf"^{_OBJECT} {words} {_OBJECT}$"
            m = re.match(pattern, s)
            if m:
                return _task_from_match(relation, m.groups(), text)
    _explain_failure(s, text)


def _task_from_match(relation: str, groups: tuple[str, ...], text: str) -> Task:
    parsed = [_parse_object(groups[i], groups[i + 1]) for i in range(0, len(groups), 2)]
    shapes = {shape for _, shape in parsed if shape is not None}
    if len(shapes) > 1:
        raise GoalError(f"a goal relates objects of one kind, got {' and '.join(sorted(shapes))} in {text!r}")
    return Task(relation, tuple(c for c, _ in parsed), shapes.pop() if shapes else "block")


def _explain_failure(s: str, text: str):
    words = set(s.split())
    unknown_colours = [w for w in words if w in _COMMON_COLOURS and w not in COLOURS]
    if unknown_colours:
        raise GoalError(f"unknown colour {unknown_colours[0]!r} in {text!r}; known colours: {', '.join(COLOURS)}")
    known = "; ".join(f"{r}: '{w[0]}'" for r, w in RELATION_WORDS.items())
    raise GoalError(
        f"cannot read the goal {text!r}. Write '<a colour shape> <relation> <a colour shape>', "
        f"e.g. 'a yellow block on top of a red block'. Known relations: {known}. "
        f"Known colours: {', '.join(COLOURS)}. Known objects: {', '.join(SHAPES)}."
    )


_COMMON_COLOURS = {"purple", "orange", "pink", "black", "white", "brown", "grey", "gray", "cyan", "magenta"}
