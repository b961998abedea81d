"""Negative goal texts for the binarised reward (paper 2.2, "Full Reward Model Training and Usage").

The reward is 1 when the goal text scores higher than every negative text, else 0, so no
threshold has to be tuned. Negatives come from the task itself:

* the other relations over the same objects, in the same order ("a yellow block on the left
  of a red block" for "a yellow block on top of a red block"); relations of another arity
  are formed where the task names enough objects (see :func:`negative_tasks`);
* the same relation with the object order swapped ("a red block on top of a yellow block"),
  except for symmetric relations, whose swapped text says the same thing.

Texts that say the same as the goal are never negatives: ``below(a, b)`` is
``on_top_of(b, a)``, so only *other* relations in the *same* order are used, never another
relation in the swapped order.

>>> [t.text for t in negative_tasks(Task("on_top_of", ("yellow", "red")))][:3]
['a yellow block on the left of a red block', 'a yellow block on the right of a red block', 'a yellow block below a red block']
>>> negative_texts("a blue puck close to a yellow puck")[-2:]  # symmetric: no swap; a complement
['a blue puck inside of a yellow puck', 'a blue puck far from a yellow puck']
"""
from __future__ import annotations

import re
from dataclasses import replace
from functools import lru_cache

from zsrm.tasks.catalogue import as_task
from zsrm.tasks.language import GoalError, Task, parse_goal, with_article
from zsrm.tasks.relations import RELATIONS
from zsrm.tasks.scene_goals import SceneGoal, read_canonical

# Relations whose predicate does not change when the two objects swap (Table 1: both read a
# centre distance). Checked against the predicates themselves in the tests.
SYMMETRIC = frozenset({"close_to", "inside_of"})

# Relations the goal implies on its own camera, which would tie with it whenever it holds:
# "a between b and c" means a is right of one and left of the other; "inside of" is "close
# to" with a smaller distance (Table 1).
IMPLIED_BY = {"in_between": frozenset({"left_of", "right_of"}), "inside_of": frozenset({"close_to"})}


# Table 1 has no words for "none of this camera's relations holds". On the front and left
# cameras one of a pair's relations nearly always holds (left or right, in front or behind),
# but two objects on the tilted camera are often neither close nor inside: without a text for
# that, "close to" would win the argmax against "inside of" on every frame. The complement
# of close to, "far from", is a caption when neither holds (:func:`complement_captions`) and a
# negative of close to. "Outside of" does the same for a block and the box: without it, the
# texts ranked against "inside of a box" (left of it, behind it, ...) are never true on the
# tilted camera, and which of them wins on a frame with the block beside the box is chance.
COMPLEMENTS = {"close_to": ("far_from", "far from"), "inside_of": ("outside_of", "outside of")}
COMPLEMENT_CAMERA = {name: RELATIONS[rel].camera for rel, (name, _) in COMPLEMENTS.items()}
# An object phrase: "red block", the box (one word), or an own scene's ("orange mug").
_PHRASE = r"([a-z]+(?: [a-z]+)*)"
_COMPLEMENT_RE = {name: re.compile(rf"^an? {_PHRASE} {words} an? {_PHRASE}$") for name, words in COMPLEMENTS.values()}


def complement_text(task: Task) -> str | None:
    """The sentence saying the task's relation does not hold, for relations that have one."""
    if task.relation not in COMPLEMENTS:
        return None
    a, b = task.phrases
    return f"{with_article(a)} {COMPLEMENTS[task.relation][1]} {with_article(b)}"


def caption_relation_camera(caption: str) -> tuple[str, str]:
    """(relation name, camera it is read on) of a caption: a Table 1 sentence or a complement,
    over zsrm's objects or an own scene's (:func:`read_caption`)."""
    for name, pattern in _COMPLEMENT_RE.items():
        if pattern.match(caption):
            return name, COMPLEMENT_CAMERA[name]
    relation = read_caption(caption).relation
    return relation, RELATIONS[relation].camera


@lru_cache(maxsize=None)
def read_caption(caption: str) -> "Task | SceneGoal":
    """A caption as the labeler writes it: a Task where zsrm's grammar reads it as written, else the
    SceneGoal of an own scene's canonical sentence (phrases zsrm's grammar does not know, or reads
    in its own words: "a red cube" as "a red block"), else the Task zsrm's grammar made of it.
    Kept per caption (both are frozen): training reads each caption's negatives at every step.
    Goals a user writes are read strictly (:func:`~zsrm.tasks.catalogue.as_task`, or
    :func:`~zsrm.tasks.scene_goals.parse_scene_goal` with the scene's phrases): an unknown
    colour there is an error, not an own scene's object."""
    try:
        task = parse_goal(caption)
    except GoalError:
        try:
            return read_canonical(caption)
        except GoalError:
            pass
        raise  # zsrm's own reading's error (an unknown colour), not the own scenes'
    if task.text == caption:
        return task
    try:  # read in zsrm's words ("a red cube" as "a red block"), but an own scene's canonical sentence
        return read_canonical(caption)
    except GoalError:
        return task


def _goal(task: "str | Task | SceneGoal") -> "Task | SceneGoal":
    """A Task of zsrm's scenes (from a sentence or a catalogue name), or an own scene's SceneGoal
    as it is: the negatives of both are built the same way (``replace`` keeps a Task's shape)."""
    return task if isinstance(task, SceneGoal) else as_task(task)


def swapped_tasks(task: Task) -> list[Task]:
    """The goal's relation over the same objects in the orders that mean something else."""
    if task.relation in SYMMETRIC:
        return []
    a, *rest = task.objects
    if len(rest) == 1:
        return [replace(task, objects=(rest[0], a))]
    # in between: put each other object in the middle; (a, c, b) means the same as (a, b, c).
    b, c = rest
    return [replace(task, objects=(b, a, c)), replace(task, objects=(c, a, b))]


def negative_tasks(task: str | Task) -> list[Task]:
    """The negatives of a task: other relations over the same objects, then the swapped order.

    For a two-object task every other two-object relation is used; in between is left out, as
    it needs a third object the task does not name. For the three-object in between, the
    two-object relations relate the first object to each of the other two. Relations the goal
    implies (:data:`IMPLIED_BY`) are left out. An own scene's :class:`SceneGoal` gets the same
    negatives over its phrases.
    """
    task = _goal(task)
    out: list[Task] = []
    first, others = task.objects[0], task.objects[1:]
    for name, rel in RELATIONS.items():
        if name == task.relation or name in IMPLIED_BY.get(task.relation, ()):
            continue
        if rel.arity == len(task.objects):
            out.append(replace(task, relation=name))
        elif rel.arity == 2 and len(task.objects) > 2:
            out += [replace(task, relation=name, objects=(first, other)) for other in others]
        # rel.arity > len(task.objects): the task names too few objects to form it.
    out += swapped_tasks(task)
    return out


def negative_texts(task: str | Task) -> list[str]:
    """Canonical texts of :func:`negative_tasks`, then the relation's complement if it has one
    ("a blue puck far from a yellow puck" for "a blue puck close to a yellow puck")."""
    task = _goal(task)
    complement = complement_text(task)
    return [t.text for t in negative_tasks(task)] + ([complement] if complement else [])


def complement_of(caption: str) -> "Task | SceneGoal | None":
    """For a complement caption ("a red block far from a blue block") the task it denies; over
    an own scene's phrases ("a red mug far from an orange plate") its SceneGoal."""
    for relation, (name, _) in COMPLEMENTS.items():
        m = _COMPLEMENT_RE[name].match(caption)
        if m:
            (a, *shape_a), (b, *shape_b) = (p.split() for p in m.groups())
            try:
                denied = Task(relation, (a, b), (shape_a or shape_b or ["block"])[0])
            except GoalError:
                denied = None
            if denied is None or complement_text(denied) != caption:
                denied = SceneGoal(relation, m.groups())
            return denied if complement_text(denied) == caption else None
    return None


def candidate_texts(task: str | Task) -> list[str]:
    """The goal's canonical text first, then its negatives: what the binarised reward ranks.

    A complement caption (a training caption, not a goal) ranks against the relation it denies.
    An own scene's :class:`SceneGoal` ranks against its negatives over the scene's phrases.
    """
    if isinstance(task, str):
        denied = complement_of(task.strip())
        if denied is not None:
            return [complement_text(denied), denied.text]
    task = _goal(task)
    return [task.text] + negative_texts(task)


def caption_candidates(caption: str) -> list[str]:
    """:func:`candidate_texts` of a labeler's caption, over zsrm's objects or an own scene's
    (:func:`read_caption`): what training ranks each caption against."""
    denied = complement_of(caption)
    if denied is not None:
        return [complement_text(denied), denied.text]
    return candidate_texts(read_caption(caption))
