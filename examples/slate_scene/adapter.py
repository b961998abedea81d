"""A scene zsrm was not built for, given to it as a new user with only a MuJoCo XML would:
no env of one's own, so zsrm builds the env from ``scene.xml`` (its bare-XML path).

    zsrm own-scene --scene examples.slate_scene.adapter:SlateScene --out runs/slate \\
        --goals "a white sphere on the left of a black box" "a teal capsule behind a yellow ellipsoid" \\
                "a yellow ellipsoid on the right of a white sphere"
"""
from __future__ import annotations

from pathlib import Path

from zsrm.envs import SceneAdapter

# The words goals will use for each object, and its body in scene.xml.
BODIES = {
    "white sphere": "white_sphere",
    "black box": "black_box",
    "teal capsule": "teal_capsule",
    "yellow ellipsoid": "yellow_ellipsoid",
}


class SlateScene(SceneAdapter):
    xml = str(Path(__file__).with_name("scene.xml"))
    objects = tuple(BODIES)
    bodies = BODIES  # privileged: the oracle, evaluation and the stand-in VLM's presence captions only
    cameras = {"front": "view_front", "left": "view_left", "tilted": "view_oblique"}
    # Exploration: objects moved up to 12 cm from where the XML puts them, the paddle's targets
    # drawn over the whole ctrlrange. Goals: objects near where the XML puts them, the paddle
    # starting beside one of them and moving 1 cm per step.
    env_kwargs = {"jitter": 0.12}
    task_env_kwargs = {"jitter": 0.05, "start": "beside", "step_size": 0.01}
    object_width = 0.05
    table_height = 0.40
