"""Goals as sentences and as tasks, the spatial relations of Table 1, and the task catalogue."""
from zsrm.tasks.catalogue import SINGLE_TASKS, TEST_TASKS, TRAIN_TASKS, resolve
from zsrm.tasks.language import COLOURS, GoalError, Task, parse_goal
from zsrm.tasks.relations import RELATIONS, WORLD_THRESHOLDS, Thresholds, camera_plane, holds_in_world

__all__ = [
    "COLOURS", "GoalError", "RELATIONS", "SINGLE_TASKS", "TEST_TASKS", "TRAIN_TASKS", "Task",
    "Thresholds", "WORLD_THRESHOLDS", "camera_plane", "holds_in_world", "parse_goal", "resolve",
]
