"""Every task is achievable: the true-state scripted controllers reach the oracle's goal."""
import gymnasium as gym
import pytest

import zsrm.envs  # noqa: F401
from zsrm.envs.rollout import make_env, random_policy, run_episode
from zsrm.envs.scripted import scripted_controller

GOALS = [
    "stack", "place_left", "place_right", "push_close",
    "a red block below a green block",
    "a red block in between a green block and a blue block",
    "a red block in front of a blue block",
    "a red block behind a blue block",
    "a red block close to a blue block",
    "place_inside",
]


@pytest.mark.parametrize("goal", GOALS)
def test_scripted_controller_reaches_the_goal(goal):
    env = make_env(goal, image_size=16)
    for seed in range(2):
        result = run_episode(env, scripted_controller, seed=seed)
        assert result["success"], f"{goal} seed {seed}"
        assert result["steps_in_goal"] > 30
        # The script put the block down: a block held in the air is hidden by the fingers on some
        # cameras, and an episode that never lets go shows no frame of the goal as it is meant.
        assert getattr(env.unwrapped, "held", None) is None, f"{goal} seed {seed}: still holding a block"


def test_random_policy_rarely_reaches_the_goal():
    env = make_env("stack", image_size=16)
    wins = sum(run_episode(env, random_policy, seed=s)["success"] for s in range(3))
    assert wins == 0


def test_inside_of_another_block_has_no_script():
    env = gym.make("zsrm/Tabletop-v0", task="a red block inside of a blue block", image_size=16)
    env.reset(seed=0)
    with pytest.raises(NotImplementedError, match="only the box is a container"):
        scripted_controller(env)
