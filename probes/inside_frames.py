"""What the two place_inside labeler probes share (``box_area_check.py``, ``inside_front_check.py``):
the goal, frames of scripted episodes with the oracle's verdicts, one verdict row, and the output.

The oracle's verdict is only compared with, never read by the labeler.
"""
from __future__ import annotations

import numpy as np

from zsrm.common.files import write_json
from zsrm.envs.rollout import episode_steps

GOAL = "a yellow block inside of a box"


def episode_frames(env, policy, seeds, cameras=("tilted",), skip: int = 5, every: int = 1):
    """Each camera's frames (after the first ``skip`` steps, every ``every``-th) and the oracle's verdicts."""
    frames, oracle = {camera: [] for camera in cameras}, []
    for seed in seeds:
        for _, obs, info, _ in list(episode_steps(env, policy, seed=seed))[skip::every]:
            for camera in cameras:
                frames[camera].append(obs[camera])
            oracle.append(bool(info["is_success"]))
    return {camera: np.stack(f) for camera, f in frames.items()}, np.array(oracle)


def verdicts(said: np.ndarray, oracle: np.ndarray) -> dict:
    """How often the labeler said the goal, wrongly, and its recall on the oracle's goal frames."""
    return {"says_goal": int(said.sum()), "false_goal": int((said & ~oracle).sum()),
            "recall": float(said[oracle].mean()) if oracle.any() else None}


def write_rows(path: str, out: dict) -> None:
    """Write the probe's file and print its rows."""
    write_json(path, out)
    for name, row in out.items():
        if name != "meta":
            print(name, row)
