"""What zsrm needs to know about the example scene, written as a user writes it.

    zsrm collect --scene examples.own_scene.adapter:OwnScene --out data/own-scene --images 200
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from examples.own_scene import ENV_ID
from zsrm.envs import SceneAdapter

# The words goals will use for each object, and the env's body for it.
BODIES = {
    "red cylinder": "red_cylinder",
    "purple cylinder": "purple_cylinder",
    "orange cylinder": "orange_cylinder",
    "wooden bowl": "bowl",
}


class OwnScene(SceneAdapter):
    env_id = ENV_ID
    xml = str(Path(__file__).with_name("scene.xml"))
    objects = tuple(BODIES)
    cameras = {"front": "cam_front", "left": "cam_side", "tilted": "cam_high"}
    # Exploration: objects anywhere on the table, 2 cm pusher steps. Goals: objects near the
    # centre, the pusher just in front of one of them (as zsrm's own task scenes start) and moving
    # in 1 cm steps: a random policy's 8 cm decisions (4 control steps) wandered off the objects.
    task_env_kwargs = {"start": "compact", "step_size": 0.01}
    object_width = 0.05  # the cylinders' diameter
    table_height = 0.30  # the table top: the labeler reads the high camera on it in metres

    def env_objects(self, phrases):
        return tuple(BODIES[p] for p in phrases)

    def object_positions(self, env) -> dict[str, np.ndarray]:
        """Privileged: read from the simulator, for the oracle and evaluation only."""
        base = env.unwrapped
        return {p: base.body_position(BODIES[p]) for p in self.objects if BODIES[p] in base.objects}


class OwnSceneSideways(OwnScene):
    """The same scene, with task scenes for sideways goals (right of, left of): the goal's objects
    one behind the other, the pusher 6 cm beside the one the goal moves, on the side it must be
    pushed from (as zsrm's pushing scene starts its pusher on the far side of the moved puck).
    From the compact start a sideways goal needs the pusher to go round an object first, and no
    reward learnt it; beside the front object on either side, PPO learnt to push it away from
    the pusher, right half the time (docs/own-scene.md, step 12)."""

    # 6 cm from the cylinder: from 1.5 cm (the compact start's) an untrained policy's small steady
    # drift pushed it across in 45% of the steps (a policy moving +0.05 a step: 32%; here 0)
    task_env_kwargs = {"start": "column", "step_size": 0.01, "reach": 0.06}

    def task_reset_options(self, goal):
        side = {"right_of": "left", "left_of": "right"}.get(goal.relation)
        return {"beside": BODIES[goal.objects[0]], "side": side} if side else None


class OwnSceneFromXml(SceneAdapter):
    """The same scene from its MuJoCo XML alone, with no env of one's own: zsrm builds the env
    (camera images in, the actuators' controls out, normalised to [-1, 1] over their ctrlrange:
    here the pusher's target position), and reads the objects' positions from the bodies named
    here (privileged). Scenes hold any subset of the four (zsrm parks the others out of sight);
    a reset moves each by up to ``jitter`` metres."""

    xml = str(Path(__file__).with_name("scene.xml"))
    env_kwargs = {"jitter": 0.1}
    objects = tuple(BODIES)
    bodies = BODIES
    cameras = {"front": "cam_front", "left": "cam_side", "tilted": "cam_high"}
    object_width = 0.05
    table_height = 0.30
