"""Goals as sentences and as tasks, the spatial relations of Table 1, the task catalogue, and
the negatives of a goal (what the binarised reward ranks it against)."""
from zsrm.tasks.catalogue import (REPORT_TASKS, SCENE_IDS, SCENE_SHAPES, SINGLE_TASKS, TEST_TASKS, TRAIN_TASKS,
                                  as_task, resolve)
from zsrm.tasks.language import COLOURS, GoalError, Task, parse_goal
from zsrm.tasks.negatives import candidate_texts, negative_tasks, negative_texts
from zsrm.tasks.relations import RELATIONS, WORLD_THRESHOLDS, Thresholds, camera_plane, holds_in_world

__all__ = [
    "COLOURS", "GoalError", "RELATIONS", "REPORT_TASKS", "SCENE_IDS", "SCENE_SHAPES", "SINGLE_TASKS", "TEST_TASKS",
    "TRAIN_TASKS", "Task", "Thresholds", "WORLD_THRESHOLDS", "as_task", "camera_plane", "candidate_texts",
    "holds_in_world", "negative_tasks", "negative_texts", "parse_goal", "resolve",
]
