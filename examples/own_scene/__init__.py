"""An example of a scene zsrm was not built for: the user's env (:mod:`.env`, its MJCF in
``scene.xml``) and the adapter that tells zsrm about it (:mod:`.adapter`).

Importing the package registers the env with gymnasium as ``OwnScene/Pusher-v0``.
"""
from gymnasium.envs.registration import register, registry

ENV_ID = "OwnScene/Pusher-v0"

if ENV_ID not in registry:
    register(id=ENV_ID, entry_point="examples.own_scene.env:OwnSceneEnv", max_episode_steps=100)
