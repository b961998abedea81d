"""The tasks of the paper: the single tasks of Figures 4-6 and the 18 + 18 tasks of section 3.3."""
from __future__ import annotations

from dataclasses import dataclass
from itertools import permutations

from zsrm.tasks.language import GoalError, Task, parse_goal

TRAIN_COLOURS = ("red", "green", "yellow")
TEST_COLOUR = "blue"  # never seen by the multi-task policy in training
MULTITASK_RELATIONS = ("on_top_of", "left_of", "right_of")  # stack, pick-place-left, pick-place-right


@dataclass(frozen=True)
class CatalogueEntry:
    name: str
    env_id: str
    goal: str

    @property
    def task(self) -> Task | None:
        """The spatial task, or None for goals that are not a relation (the pendulum)."""
        return None if self.env_id == PENDULUM_ID else parse_goal(self.goal)


TABLETOP_ID = "zsrm/Tabletop-v0"
PUSHING_ID = "zsrm/Pushing-v0"
PENDULUM_ID = "zsrm/DoublePendulum-v0"

# The two object scenes: the env each is registered as, and the shape of its objects. The order
# is the scenes' index wherever data store a scene as a number (0 tabletop, 1 pushing).
SCENE_IDS = {"tabletop": TABLETOP_ID, "pushing": PUSHING_ID}
SCENE_SHAPES = {"tabletop": "block", "pushing": "puck"}

SINGLE_TASKS: dict[str, CatalogueEntry] = {
    e.name: e
    for e in (
        CatalogueEntry("push_close", PUSHING_ID, "a blue puck close to a yellow puck"),
        CatalogueEntry("stack", TABLETOP_ID, "a yellow block on top of a red block"),
        CatalogueEntry("place_right", TABLETOP_ID, "a yellow block on the right of a red block"),
        CatalogueEntry("place_left", TABLETOP_ID, "a yellow block on the left of a red block"),
        # One task for each further relation of Table 1 (inside of: into the tabletop's open box).
        CatalogueEntry("place_below", TABLETOP_ID, "a red block below a yellow block"),
        CatalogueEntry("place_between", TABLETOP_ID, "a yellow block in between a red block and a green block"),
        CatalogueEntry("place_front", TABLETOP_ID, "a yellow block in front of a red block"),
        CatalogueEntry("place_behind", TABLETOP_ID, "a yellow block behind a red block"),
        CatalogueEntry("place_inside", TABLETOP_ID, "a yellow block inside of a box"),
        CatalogueEntry("pendulum", PENDULUM_ID, "an inverted pendulum standing upright"),
    )
}


# The spatial single tasks every report and evaluation runs (one per scene and relation kind).
REPORT_TASKS = ("stack", "place_left", "place_right", "push_close")
# Every catalogue task with a spatial goal (all but the pendulum).
SPATIAL_TASKS = tuple(name for name, entry in SINGLE_TASKS.items() if entry.env_id != PENDULUM_ID)
# The same, one per relation of Table 1 in its order: what zsrm sweep trains by default (issue 52).
LEARNING_TASKS = ("stack", "place_left", "place_right", "place_below", "place_between", "place_front", "place_behind",
                  "place_inside", "push_close")


def _multitask(pairs) -> list[Task]:
    return [Task(rel, pair) for rel in MULTITASK_RELATIONS for pair in pairs]


# 3 relations x 6 ordered pairs of the three training colours.
TRAIN_TASKS: list[Task] = _multitask(list(permutations(TRAIN_COLOURS, 2)))
# 3 relations x 6 ordered pairs of blue with one training colour.
TEST_TASKS: list[Task] = _multitask(
    [p for c in TRAIN_COLOURS for p in ((TEST_COLOUR, c), (c, TEST_COLOUR))]
)


def choice_colours(task: Task) -> tuple[str, ...]:
    """The colours a goal's choice scene (``zsrm train --choice``) may hold as its third block:
    the training colours the goal does not name (one for a training task, so none of their scenes
    shows blue; two for a test task), else blue.

    >>> choice_colours(parse_goal("a blue block on top of a red block"))
    ('green', 'yellow')
    """
    return tuple(c for c in TRAIN_COLOURS if c not in task.objects) or (TEST_COLOUR,)


def choice_colour(task: Task) -> str:
    """The third block of a goal's choice scene when one is not given: the first of
    :func:`choice_colours`.

    >>> choice_colour(parse_goal("a yellow block on top of a red block"))
    'green'
    """
    return choice_colours(task)[0]


def resolve(name_or_goal: str) -> CatalogueEntry:
    """A catalogue name ("stack") or a goal sentence to the entry that runs it."""
    if name_or_goal in SINGLE_TASKS:
        return SINGLE_TASKS[name_or_goal]
    try:
        task = parse_goal(name_or_goal)
    except GoalError as err:
        raise GoalError(f"{err} (or name a catalogue task: {', '.join(SINGLE_TASKS)})") from None
    env_id = PUSHING_ID if task.scene == "pushing" else TABLETOP_ID
    return CatalogueEntry(task.text, env_id, task.text)


def as_task(task: "str | Task", shape: str | None = None) -> Task:
    """A Task from a Task, a goal sentence or a catalogue name (GoalError for anything that is
    not a spatial goal); with ``shape``, also checks that the goal names objects of that shape.

    >>> as_task("stack").text
    'a yellow block on top of a red block'
    """
    if isinstance(task, str):
        entry = SINGLE_TASKS.get(task)
        task = parse_goal(entry.goal if entry else task)
    if not isinstance(task, Task):
        raise GoalError(f"a goal must be a sentence or a Task, got {type(task).__name__}")
    if shape is not None and task.shape != shape:
        raise GoalError(f"this scene has {shape}s, but the goal {task.text!r} names {task.shape}s")
    return task
