"""What a goal sentence trains on: its catalogue entry and the camera its relation is read on."""
from __future__ import annotations

from zsrm.tasks.catalogue import PENDULUM_ID, CatalogueEntry, resolve
from zsrm.tasks.relations import RELATIONS


def task_entry(goal: str) -> CatalogueEntry:
    """The catalogue entry of a goal: a spatial task, or the pendulum."""
    return resolve(goal)


def is_pendulum(goal: str) -> bool:
    return task_entry(goal).env_id == PENDULUM_ID


def goal_camera(goal: str) -> str:
    """The camera the goal's relation is read on (Table 1): front, left or tilted; the
    pendulum's one camera, front."""
    entry = task_entry(goal)
    if entry.env_id == PENDULUM_ID:
        return "front"
    return RELATIONS[entry.task.relation].camera
