"""The scenes, registered with gymnasium under ``zsrm/``; a user's own scene comes in through a
:class:`SceneAdapter` (:mod:`zsrm.envs.adapter`).

>>> import gymnasium as gym, zsrm.envs
>>> env = gym.make("zsrm/Tabletop-v0", task="a yellow block on the right of a red block",
...                cameras=("front", "left", "tilted"), image_size=64)
"""
from gymnasium.envs.registration import register, registry

from zsrm.envs.adapter import SceneAdapter, SceneAdapterError, load_adapter, register_scene
from zsrm.envs.pendulum import DoublePendulumPixelEnv
from zsrm.envs.pushing import PushingEnv
from zsrm.envs.tabletop import TabletopEnv
from zsrm.tasks.catalogue import PENDULUM_ID, PUSHING_ID, TABLETOP_ID

EPISODE_STEPS = 100

SCENES = {TABLETOP_ID: TabletopEnv, PUSHING_ID: PushingEnv, PENDULUM_ID: DoublePendulumPixelEnv}

for _id, _cls in SCENES.items():
    if _id not in registry:
        register(id=_id, entry_point=f"{_cls.__module__}:{_cls.__name__}",
                 max_episode_steps=EPISODE_STEPS if _id != PENDULUM_ID else 1000)


def layout_version(env_id: str) -> int:
    """How a scene's task episodes start, as a version (its class's ``layout_version``)."""
    return getattr(SCENES[env_id], "layout_version", 1)


__all__ = ["DoublePendulumPixelEnv", "PushingEnv", "TabletopEnv", "EPISODE_STEPS", "SCENES", "layout_version",
           "SceneAdapter", "SceneAdapterError", "load_adapter", "register_scene"]
