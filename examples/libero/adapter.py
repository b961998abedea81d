"""LIBERO-Spatial scenes (a Panda, two black bowls, a plate, a cookie box, a ramekin, a cabinet
and a stove) for zsrm, written as a user writes an adapter. Runs in ``.venv-bench``:

    .venv-bench/bin/zsrm own-scene --scene examples.libero.adapter:SpatialBetween --out runs/libero \\
        --goals "a black bowl on top of a plate" "a black bowl on top of a cookie box"

Goals are judged by LIBERO's own BDDL predicates (``_eval_predicate(["on", a, b])``), never by
zsrm's oracle. The second black bowl is always parked: two objects the same words name could
not be told apart by a goal.
"""
from __future__ import annotations

import gymnasium as gym
import numpy as np

from examples.libero.env import LIBERO_CAMERAS, LiberoTableEnv
from zsrm.envs import SceneAdapter

# The words goals use for each object -> LIBERO's object name.
OBJECTS = {"black bowl": "akita_black_bowl_1", "plate": "plate_1", "cookie box": "cookies_1",
           "ramekin": "glazed_rim_porcelain_ramekin_1"}
ALL_OBJECTS = (*OBJECTS.values(), "akita_black_bowl_2")


class SpatialBetween(SceneAdapter):
    """LIBERO-Spatial task 0: "pick up the black bowl between the plate and the ramekin and place it on the plate"."""

    task = ("libero_spatial", 0)
    objects = tuple(OBJECTS)
    bodies = {p: f"{n}_main" for p, n in OBJECTS.items()}  # privileged: oracle, evaluation, captions
    cameras = dict(zip(("front", "left", "tilted"), LIBERO_CAMERAS))  # added: see env.py
    subsets = True  # make_env parks the objects a scene leaves out
    object_width = 0.08
    table_height = 0.9  # LIBERO's table_offset z
    env_kwargs = {"p_stack": 0.25}
    task_env_kwargs = {"task_layout": True}  # a policy's scenes: LIBERO's own placement

    def make_env(self, cameras, image_size=64, objects=None, task=False):
        held = tuple(OBJECTS[p] for p in (self.objects if objects is None else objects))
        kwargs = {**self.env_kwargs, **(self.task_env_kwargs if task else {})}
        # A LIBERO env takes 6 s to build and zsrm asks for one per subset of objects (15 here):
        # one env per task and settings is kept, and each request holds its own subset.
        key = (self.task, tuple(cameras), int(image_size), tuple(sorted(kwargs.items())))
        if key not in _ENVS:
            _ENVS[key] = LiberoTableEnv(self.task, objects=held, all_objects=ALL_OBJECTS, cameras=tuple(cameras),
                                        image_size=image_size, **kwargs)
        env = _ENVS[key]
        env.held = held
        return gym.wrappers.TimeLimit(_Shared(env, held), max_episode_steps=100)


_ENVS: dict = {}  # kept envs, closed when the process ends


class _Shared(gym.Wrapper):
    """A kept env lent to one caller, holding the caller's objects from each reset on (zsrm keeps
    one env per subset and goes back to them: until 2026-12-07 the env held the last subset asked
    for, and 95% of LIBERO's exploration frames held the bowl and the cookie box alone). Its
    close() leaves the env open for the next caller."""

    def __init__(self, env, held: tuple[str, ...]):
        super().__init__(env)
        self.held = held

    def reset(self, **kwargs):
        self.env.held = self.held
        return self.env.reset(**kwargs)

    def close(self):
        pass


class SpatialNextToCookies(SpatialBetween):
    """LIBERO-Spatial task 6: "pick up the black bowl next to the cookie box and place it on the plate"."""

    task = ("libero_spatial", 6)


# The benchmark's own checks, per goal sentence: LIBERO's BDDL predicate (On upper lower).
PREDICATES = {
    "a black bowl on top of a plate": ("on", OBJECTS["black bowl"], OBJECTS["plate"]),
    "a black bowl on top of a cookie box": ("on", OBJECTS["black bowl"], OBJECTS["cookie box"]),
    "a ramekin on top of a plate": ("on", OBJECTS["ramekin"], OBJECTS["plate"]),
}
PREDICATE_NAMES = {g: f"LIBERO _eval_predicate({list(p)})" for g, p in PREDICATES.items()}


def predicate(env, goal: str) -> bool:
    """LIBERO's ``_eval_predicate`` for ``goal`` on ``env`` now."""
    return bool(env.unwrapped.rs._eval_predicate(list(PREDICATES[goal])))


def place_goal(env, goal: str, rng):
    """Evaluation only: the upper object dropped from 7 cm onto the lower (as the goal's On
    region says), settled for 0.3 s; returns the new observation."""
    base = env.unwrapped
    _, upper, lower = PREDICATES[goal]
    xyz = base.data.xpos[base.model.body(base.body_name(lower)).id].copy()
    base._place(upper, xyz + np.array([*rng.uniform(-0.01, 0.01, 2), 0.07]))
    return base.settle(steps=150)
