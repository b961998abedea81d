"""robosuite's Stack (a Panda, a red cube and a green cube) for zsrm, written as a user writes
an adapter. Runs in ``.venv-bench`` (``make bench-setup``):

    .venv-bench/bin/zsrm own-scene --scene examples.robosuite.adapter:StackScene --out runs/rs \\
        --goals "a red cube on top of a green cube" "a green cube on top of a red cube"

Goals are judged by robosuite's own check (:func:`predicate`), never by zsrm's oracle.
"""
from __future__ import annotations

import gymnasium as gym
import numpy as np

from examples.robosuite.env import TABLE_CAMERAS, RobosuiteTableEnv
from zsrm.envs import SceneAdapter

# The words goals use for each object -> robosuite's Stack attribute (cubeA: red, 4 cm; cubeB: green, 5 cm).
OBJECTS = {"red cube": "cubeA", "green cube": "cubeB"}


class StackScene(SceneAdapter):
    objects = tuple(OBJECTS)
    bodies = {"red cube": "cubeA_main", "green cube": "cubeB_main"}  # privileged: oracle, evaluation, captions
    cameras = {"front": "table_front", "left": "table_left", "tilted": "table_tilted"}  # added: see env.py
    subsets = True  # make_env parks the cubes a scene leaves out
    object_width = 0.045
    table_height = 0.8  # robosuite's table_offset z
    env_kwargs = {"p_stack": 0.25}  # exploration: zsrm's layouts (a quarter of them with a cube on the other)
    task_env_kwargs = {"task_layout": True}  # a policy's scenes: robosuite's own placement

    def make_env(self, cameras, image_size=64, objects=None, task=False):
        held = tuple(OBJECTS[p] for p in (self.objects if objects is None else objects))
        kwargs = {**self.env_kwargs, **(self.task_env_kwargs if task else {})}
        env = RobosuiteTableEnv("Stack", objects=held, all_objects=tuple(OBJECTS.values()), cameras=tuple(cameras),
                                image_size=image_size, **kwargs)
        return gym.wrappers.TimeLimit(env, max_episode_steps=100)


# The benchmark's own checks, per goal sentence: robosuite's Stack._check_success (cubeA lifted,
# touching cubeB, not grasped). The reverse goal calls the same method with the cubes' roles
# swapped: robosuite's logic, not zsrm's.
PREDICATES = {
    "a red cube on top of a green cube": ("cubeA", "cubeB"),
    "a green cube on top of a red cube": ("cubeB", "cubeA"),
}


def predicate(env, goal: str) -> bool:
    """robosuite's ``Stack._check_success()`` for ``goal`` (upper, lower cube) on ``env`` now."""
    rs = env.unwrapped.rs
    upper, lower = PREDICATES[goal]
    if upper == "cubeA":
        return bool(rs._check_success())
    saved = rs.cubeA, rs.cubeB, rs.cubeA_body_id, rs.cubeB_body_id
    rs.cubeA, rs.cubeB, rs.cubeA_body_id, rs.cubeB_body_id = saved[1], saved[0], saved[3], saved[2]
    try:
        return bool(rs._check_success())
    finally:
        rs.cubeA, rs.cubeB, rs.cubeA_body_id, rs.cubeB_body_id = saved


PREDICATE_NAMES = {
    "a red cube on top of a green cube": "robosuite Stack._check_success() (cubeA=red on cubeB=green)",
    "a green cube on top of a red cube": "robosuite Stack._check_success() with cubeA and cubeB swapped",
}


def place_goal(env, goal: str, rng):
    """Evaluation only: the cubes placed as robosuite's Stack goal region says (the upper cube
    resting on the lower, within 6 mm of its centre), settled for 0.1 s of simulated time (the
    check asks for contact); returns the new observation."""
    base = env.unwrapped
    upper, lower = PREDICATES[goal]
    xyz = base.data.xpos[base.rs.sim.model.body_name2id(base.body_name(lower))].copy()
    xyz[2] += base.half_height(lower) + base.half_height(upper) + 0.002
    base._place(upper, xyz + np.array([*rng.uniform(-0.006, 0.006, 2), 0.0]))
    return base.settle(steps=50)
