"""What a goal sentence trains on: its catalogue entry and the camera its relation is read on.

With ``scene`` (a user's own scene, ``module:Class`` or a registered id of a
:class:`zsrm.envs.SceneAdapter`), the goal is read over that scene's objects
(:func:`scene_goal`) instead of zsrm's catalogue.
"""
from __future__ import annotations

from functools import lru_cache

from zsrm.tasks.catalogue import PENDULUM_ID, CatalogueEntry, resolve
from zsrm.tasks.relations import RELATIONS


def task_entry(goal: str) -> CatalogueEntry:
    """The catalogue entry of a goal: a spatial task, or the pendulum."""
    return resolve(goal)


@lru_cache(maxsize=None)
def scene_goal(goal: str, scene: str):
    """The :class:`~zsrm.tasks.scene_goals.SceneGoal` of a goal sentence over an own scene's
    objects (GoalError, one line listing them, when it does not read)."""
    from zsrm.envs.adapter import load_adapter
    from zsrm.tasks.scene_goals import parse_scene_goal

    adapter = load_adapter(scene)
    return parse_scene_goal(goal, adapter.objects, scene=adapter.name)


def is_pendulum(goal: str, scene: str | None = None) -> bool:
    return not scene and task_entry(goal).env_id == PENDULUM_ID


def goal_text(goal: str, scene: str | None = None) -> str:
    """The canonical sentence of a goal (of a catalogue name: its entry's goal), as rewards read it."""
    return scene_goal(goal, scene).text if scene else task_entry(goal).goal


def goal_camera(goal: str, scene: str | None = None) -> str:
    """The camera the goal's relation is read on (Table 1): front, left or tilted; the
    pendulum's one camera, front."""
    if scene:
        return RELATIONS[scene_goal(goal, scene).relation].camera
    entry = task_entry(goal)
    if entry.env_id == PENDULUM_ID:
        return "front"
    return RELATIONS[entry.task.relation].camera
